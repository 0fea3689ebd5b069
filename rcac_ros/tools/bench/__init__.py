"""Benchmarks behind ``rcac bench``: one module per benchmark (doc/tools.md)."""
