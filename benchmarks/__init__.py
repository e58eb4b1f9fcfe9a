"""Speed figures against physical limits; run them all with ``python -m benchmarks``."""
