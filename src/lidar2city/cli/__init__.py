"""The command-line interface: thin click commands, one module per subcommand."""
