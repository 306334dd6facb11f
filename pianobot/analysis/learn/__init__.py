"""`pianobot fit`: learned maps from press parameters to MIDI outcome (grouped CV, saved
predictors) and the predictor interface `play` uses."""
