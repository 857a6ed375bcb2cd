"""Where light starts and which way it goes: lamps, sun and sky, their directions, sampling by power."""
