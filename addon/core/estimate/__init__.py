"""Tallies in, estimates out: chunk tallies, batch means, the paper's error model, the chunk plan."""
