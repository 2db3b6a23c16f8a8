"""phenorover's one source of truth: messages, keys, transport, config, clock, geometry."""
