"""Model types shared by every layer (below io): the lens grid, CFA patterns, provenance records."""
