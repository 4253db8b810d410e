"""Study: outcome sensitivity (its question and commands: README.md)."""
