"""pianobot: experiment runner and data pipeline for robotic piano keystroke research."""

__version__ = "0.1.0"
