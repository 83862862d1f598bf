"""plugcell.twin."""
