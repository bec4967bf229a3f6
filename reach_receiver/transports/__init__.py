"""Transports: the byte and message channels drivers talk through (serial, SCPI, UDP, USB)."""
