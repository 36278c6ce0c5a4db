"""Benchmarks for featurewarp (``make bench``); see benchmarks/run.py."""
