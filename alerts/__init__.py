"""Masks -> hazard sectors -> smoothing -> CAN and serial senders."""
