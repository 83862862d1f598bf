"""File formats: robot description files and measurement files.  The pure-math
packages receive the parsed, validated objects and never touch files."""
