"""Light maps from photographs of a probe (issue 11).

Modules, one paper each: the mirror ball (Debevec 1998), a diffuse object of known geometry
(:mod:`ffls.probes.hougen_ahuja`), cast shadows (:mod:`ffls.probes.sato_sato_ikeuchi`) and POCS
(:mod:`ffls.probes.singh_ahuja`); model source sets and their light maps in
:mod:`ffls.probes.sources`; model selection and evaluation in :mod:`ffls.probes.selection` and
:mod:`ffls.probes.evaluate`.
"""
