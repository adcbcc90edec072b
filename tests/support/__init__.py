"""Helpers shared by several test modules (importable because pytest adds the repo root)."""
