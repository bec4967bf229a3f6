"""The front-end model: what sits behind each switch position, signal paths and interlocks."""
