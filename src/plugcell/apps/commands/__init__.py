"""Sub-commands of the ``plugcell`` CLI: thin shells over the library (argument
parsing, file I/O, printing).  No algorithm lives here."""
