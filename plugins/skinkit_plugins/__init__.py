"""skinkit's built-in plugins. Each imports only the public skinkit API and registers by entry point."""
