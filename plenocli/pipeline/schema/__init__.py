"""What each stage takes: one module per stage holding ``PARAMS`` (and, when parameters must
agree with each other, ``check``), light enough for ``--help``; see plenocli.pipeline.params."""
