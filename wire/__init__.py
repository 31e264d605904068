"""wire: the binary wire format between the server and every viewer, in one neutral package.

Both sides import it (server encodes, clients decode); neither imports the other.

Modules:
    protocol     message kinds, the 32-byte frame header, payload encodings, close codes (Python)
    protocol.js  its JavaScript twin for the browser viewer (served at ``/js/protocol.js``),
                 checked against the Python encoder by ``tests/clients/web/test_js_units.py``
"""

from pathlib import Path

JS_PROTOCOL = Path(__file__).with_name("protocol.js")
"""The JavaScript twin of :mod:`wire.protocol`, served to browsers at ``/js/protocol.js``."""
