"""plugcell.compensation."""
