"""File formats: robot description files, measurement files, PARAMS.json and the
residual file (:mod:`.params`), plans, nests, residual models, the calibration report.
The pure-math packages receive the parsed, validated objects and never touch files."""
