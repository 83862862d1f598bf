"""plugcell.apps.ui."""
