"""Self-contact of a folding pattern along its motion (:mod:`.collisions`)."""
