"""ffls: the Free-form Light Stage (Masselus, Dutre, Anrys 2002), relighting real objects from photographs.

The library is importable without a window system. GPU code receives a ``moderngl.Context`` from
its caller (:func:`ffls.gpu.context.create_headless_context` or the viewer's window).
"""
__version__ = "0.1.0"
