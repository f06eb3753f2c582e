"""A model file as producer and consumer both see it: read and its digest (``read``), signatures
(``trust``) and the known-answer self-test (``selftest``). Below both ``export``, which seals and
signs, and ``runtime``, which verifies and runs; torch-free."""
