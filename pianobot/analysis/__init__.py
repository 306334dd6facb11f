"""Analysis of stored runs: the grey-box fitter and its uses (identify, discover), learned maps
(learn), sequence models (sequence) and the plausibility checks of their results."""
