"""One module per stage: read the inputs, call the processing function, write with provenance."""
