"""Readers for PSS/E RAW and DYR files and MATPOWER case data."""
