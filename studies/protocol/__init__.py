"""Study: the protocol's headline (its question and commands: README.md)."""
