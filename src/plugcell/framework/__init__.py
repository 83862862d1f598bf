"""plugcell.framework."""
