"""Exporters: geometry out of a trained field."""
