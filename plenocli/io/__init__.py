"""Readers and writers. Everything that touches a file lives here (and in plenocli.pipeline)."""
