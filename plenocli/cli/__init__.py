"""The command line: thin click commands over plenocli.pipeline stages."""
