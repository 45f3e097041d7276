"""CGE generators (placeholder)."""
