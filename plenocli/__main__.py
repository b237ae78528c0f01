from plenocli.cli.main import cli

cli()
