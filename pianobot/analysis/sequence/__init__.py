"""Sequence models: how a stroke's outcome depends on the strokes before it (`fit --model sequence`)."""
