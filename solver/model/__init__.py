"""The data model: hairstyles, characters, units and errors (nothing else in solver is below it)."""
