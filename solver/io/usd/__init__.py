"""USD through usd-core, what the hair reader (:mod:`hairport.solver.io.hair.usd`) and the character
reader (:mod:`hairport.solver.io.character.usd`) share: opening a stage without composing any file it
names (:mod:`.stage`, with its length unit) and the walk that finds every file a layer names
(:mod:`.assets`). Each reader stays beside the other formats of its kind, whose records and checks it
uses; both run in the sandbox's child (:mod:`hairport.solver.io.sandbox`)."""
