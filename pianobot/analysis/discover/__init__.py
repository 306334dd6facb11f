"""`pianobot discover`: which effects beyond the study's linear model the measurements need,
found by the grey-box fitter (candidates, calibrated decision rule, residual search)."""
