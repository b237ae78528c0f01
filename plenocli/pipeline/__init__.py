"""Stages (file in, file out, with provenance), their registry, YAML configs and the runner."""
