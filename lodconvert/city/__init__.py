"""City policy, free of file formats: the source LoDs that fill each level slot and the finest
of them (:mod:`.lods`), plot radii (γ) from the objects' spacing (:mod:`.plots`), the LOD1
prism derived where a source lacks one (:mod:`.prisms`), LOD parents over grid cells
(:mod:`.hlod`) and their block proxies (:mod:`.blocks`). docs/cities.md
explains each."""
