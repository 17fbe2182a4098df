"""Pictures (:mod:`.pictures`) and the interactive HTML view (:mod:`.view`) of a design."""
