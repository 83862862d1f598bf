"""plugcell.services."""
