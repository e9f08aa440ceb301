"""``rbc monitor eval``: the misbehaviour monitor measured the way a reviewer of the field would accept, on the
headless simulator (runs as data in :mod:`.runset`, the scoring rules in :mod:`.scoring`)."""
