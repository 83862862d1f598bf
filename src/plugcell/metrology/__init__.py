"""plugcell.metrology."""
