"""Differentiable capture corruptions (print-and-photo), each a registered plugin."""
