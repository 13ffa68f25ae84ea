"""Small functions that compose the steps; the CLI is a thin layer over them."""
