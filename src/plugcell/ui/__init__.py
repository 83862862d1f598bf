"""plugcell.ui."""
