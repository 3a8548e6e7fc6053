"""Analysis of files lodconvert wrote, away from the conversion core. Chains are read back
through their format's ``read_back`` (:func:`lodconvert.io.read_chains`) and used as the
:class:`~lodconvert.model.LodChain` and :class:`~lodconvert.model.Level` they are.

- :mod:`.render`: what the renderers share: :class:`~.render.OffscreenRenderer` (one EGL
  context), view and projection matrices, view directions on a sphere, and the pixel width of
  declared point sizes;
- :mod:`.silhouette`: :class:`~.silhouette.SilhouetteRenderer`, coverage masks of meshes,
  point clouds and chain levels;
- :mod:`.evaluate`: fidelity against the source mesh (``lodconvert evaluate``): silhouette
  P/R/F on a protocol and within each level's range, Chamfer/Hausdorff, counts, and the
  source's objects paired with the chains;
- :mod:`.contact_sheet`: the source and each level side by side, differences coloured;
- :mod:`.bench`: frame time of instance grids drawing a chain's levels against its original
  mesh (``lodconvert bench``), with its instanced :class:`~.bench.GridRenderer`.

GL contexts are made when a renderer is created, never at import.
"""
