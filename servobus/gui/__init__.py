"""``servobus gui``: a browser app to command, tune and monitor drives over the Axis API.

The server side (Starlette + uvicorn) is an ordinary async client of
:class:`servobus.axis.base.AsyncAxis`: it knows no protocol. The browser side is plain ES
modules and a vendored uPlot under ``static/`` (no CDN, no build step). Pure logic that the
tests check on synthetic signals lives in its own modules: :mod:`.ring`, :mod:`.decimate`,
:mod:`.trigger`, :mod:`.frames`, :mod:`.step_metrics`.
"""
