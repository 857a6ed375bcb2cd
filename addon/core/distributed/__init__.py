"""Where chunks run: this machine's threads, or a Dask cluster."""
