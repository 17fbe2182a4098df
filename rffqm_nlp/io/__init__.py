"""Files other tools open: FOLD 1.2 (:mod:`.foldfile`) and the exporters (:mod:`.export`)."""
