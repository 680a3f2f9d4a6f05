"""Tests of `runtime.protocol`'s modules one by one (the protocol as a whole:
``tests/runtime/test_protocol.py``)."""
