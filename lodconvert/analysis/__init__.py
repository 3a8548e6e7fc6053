"""Analysis of files lodconvert wrote, away from the conversion core. Chains are read back
through their format's ``read_back`` (:func:`lodconvert.io.read_chains`) and used as the
:class:`~lodconvert.model.LodChain` and :class:`~lodconvert.model.Level` they are.

- :mod:`.render` and :mod:`.silhouette`: the offscreen EGL renderers, view matrices, coverage
  masks of meshes, point clouds and chain levels;
- :mod:`.evaluate` and :mod:`.contact_sheet`: fidelity against the source mesh (``lodconvert
  evaluate``, ``docs/fidelity.md``);
- :mod:`.bench`: frame time of instance grids (``lodconvert bench``); :mod:`.city_draw`,
  :mod:`.city_select`, :mod:`.city_cameras`, :mod:`.line_of_sight` and :mod:`.city_render`:
  walks and flights through a city (``docs/render-bench.md``).

GL contexts are made when a renderer is created, never at import.
"""
