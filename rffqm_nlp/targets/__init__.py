"""What a design aims at: surfaces r(u, v) (:mod:`.surfaces`, which users reach as
``rq.surfaces``: the :class:`~.parametric.Surface` of :mod:`.parametric`, the built-ins of
:mod:`.builtins`, :mod:`.custom`, the user's code of :mod:`.user_code`, the grids and point
sets of :mod:`.point_sets`), meshes and point clouds (:mod:`.meshes`, whose steps are
:mod:`.mesh_input`, :mod:`.mesh_topology`, :mod:`.parametrization`, :mod:`.mesh_domain` and
:mod:`.splines`), shape measures (:mod:`.shape`), curvature maps (:mod:`.curvature`)."""
