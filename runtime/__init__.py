"""coral runtime package."""
