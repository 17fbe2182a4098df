"""Self-contact of a folding pattern along its motion: :mod:`.collisions` is the public face,
built of :mod:`.panels` (the panels and their table along the motion), :mod:`.narrow`
(exact distances), :mod:`.broad` (the pairs a step must look at), :mod:`.motion` (the first
contact along the motion) and :mod:`.vectors` (arithmetic over short axes)."""
