"""Device-family models: parameter tables, status decoding, counts per revolution."""
