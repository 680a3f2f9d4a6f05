"""Tests of runtime.watch: the state model, the server, the command."""
