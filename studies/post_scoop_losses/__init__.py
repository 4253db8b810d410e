"""Study: losses after the scoop (its question and commands: README.md)."""
