"""`pianobot identify`: the keystroke model's parameters (and the piano's readout) fitted to
stored runs, with intervals and provenance, written as a model file."""
