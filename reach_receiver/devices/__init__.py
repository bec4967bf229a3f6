"""Instrument drivers, each written against a transport and doing no I/O until connected."""
