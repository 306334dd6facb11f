"""`python -m pianobot` runs the command line."""

from pianobot.cli import main

main()
