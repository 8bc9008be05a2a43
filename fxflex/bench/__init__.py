"""fxflex.bench"""
