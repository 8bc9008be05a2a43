"""fxflex.beam"""
