"""Cross sections of any shape (issue 14): outlines and their finite-element properties."""
