"""The keystroke's physics: the study's 2-DoF model (`msd`), its linear system and inverse,
the arm's moves (`trajectory`, `approach`), effects, the piano's readout, the compiled simulator
and the simulated world a sim rig runs."""
