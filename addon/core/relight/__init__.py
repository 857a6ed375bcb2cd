"""Per-source results recombined with new strengths and colours, and sources re-solved alone."""
