"""The studio: a local web app over the library (``deepmorph studio``, docs/studio.md).

:mod:`deepmorph.studio.app` holds the ASGI application and its handlers, each a thin call into
the library; :mod:`~deepmorph.studio.drawing` reads and annotates the artist's drawing;
:mod:`~deepmorph.studio.jobs` keeps the training queue, whose runs
:mod:`~deepmorph.studio.worker` trains in a child process; :mod:`~deepmorph.studio.cli` is the
command. The page itself (``static/``) is plain HTML, CSS and JavaScript, served from the
package: nothing is fetched from the network.
"""
