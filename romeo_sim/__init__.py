"""coral romeo_sim package."""
