"""``python -m runtime.fuzz MISSION ...``: the same as ``coral-run fuzz MISSION ...``."""

from runtime.fuzz.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
