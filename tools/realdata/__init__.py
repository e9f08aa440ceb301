"""Real Udacity-simulator recordings: the public manifest, fetching, statistics and cleaning (``rbc data``)."""
