"""ffls: the Free-form Light Stage (Masselus, Dutre, Anrys 2002), relighting real objects from photographs.

The library is importable without a window system. GPU code receives a ``moderngl.Context`` from
its caller (:func:`ffls.gpu.context.create_headless_context` or the viewer's window).
"""
__version__ = "0.1.0"

#: The one line of a Ctrl-C before any command ran (said by ``ffls.__main__`` and ``ffls.cli``;
#: ``ffls.__main__`` imports ``ffls.cli`` only once it can answer it)
INTERRUPTED_LINE = "ffls: interrupted; nothing was done"
