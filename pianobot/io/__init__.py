"""Reading other people's formats into runs: keystroke logs, force captures, Motive mocap takes,
MIDI song files; each import writes a new run (`run_output`); `importers` is the entry."""
