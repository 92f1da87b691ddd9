"""The parameter editor region: the form (editor), one input per parameter kind
(inputs) and reading the fields back (changes)."""
