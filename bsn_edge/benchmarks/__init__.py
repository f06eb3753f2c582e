"""Benchmarks of bsn-edge: each module measures one thing and writes results/<name>.json + .md."""
