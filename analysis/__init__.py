"""coral analysis package."""
