"""The chunked reflectance field on disk (Zarr v3): format and provenance (:mod:`ffls.store.field`),
the checked float16 conversion (:mod:`ffls.store.float16`) and the resumable ingest of a capture's
photos (:mod:`ffls.store.ingest`). docs/scale.md describes the layout and the commands."""
