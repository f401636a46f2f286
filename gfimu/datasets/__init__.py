"""Readers of public and recorded datasets."""
