"""Built-in test and demo data: toy and MakeHuman characters, procedural grooms, asset download. Never imported by the pipeline."""
