"""Study: stress search (its question and commands: README.md)."""
