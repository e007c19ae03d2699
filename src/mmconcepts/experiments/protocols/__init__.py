"""Protocols several chapters share: the speech corpus (:mod:`.speech`) and the sound-motion pairs of
chapters 6 and 7 (:mod:`.pairs`). A chapter imports these, never another chapter."""
