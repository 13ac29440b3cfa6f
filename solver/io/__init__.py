"""File formats: hair and characters, one module (or package, when a format needs several) per format
behind a registry each (:mod:`.hair`, :mod:`.character`); what both kinds share: USD stages
(:mod:`.usd`), the refusal of other files (:mod:`.external`), the child process foreign parsers run
in (:mod:`.sandbox`)."""
