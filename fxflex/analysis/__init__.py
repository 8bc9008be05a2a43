"""fxflex.analysis"""
