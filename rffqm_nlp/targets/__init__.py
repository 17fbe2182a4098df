"""What a design aims at: surfaces r(u, v) (:mod:`.surfaces`), meshes and point clouds
(:mod:`.meshes`), shape measures (:mod:`.shape`), curvature maps (:mod:`.curvature`)."""
