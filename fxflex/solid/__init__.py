"""fxflex.solid"""
