"""Input and output: log files, estimates, and the readers of recorded formats.

Readers of recorded formats live in :mod:`gfimu.io.readers`, one module per
format, found by :func:`gfimu.io.readers.reader_names`.
"""
