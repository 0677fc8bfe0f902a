"""Training logs for outside tools (TensorBoard)."""
