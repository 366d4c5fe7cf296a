"""Test-session settings: the distance budget's on-disk cache (``multilat.budget``) goes to a
directory of this session, so the tests neither read a user's cache nor write to it."""

import os
import tempfile

_CACHE = tempfile.mkdtemp(prefix="multilat-test-cache-")
os.environ.setdefault("MULTILAT_CACHE_DIR", _CACHE)
