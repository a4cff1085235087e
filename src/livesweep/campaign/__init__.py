"""A flight-test campaign: every flight (log file) and test point in one SQLite database.

``livesweep.campaign.open(path)`` opens or creates it (:class:`Campaign`); ``Campaign.add(paths)``
adds logs (identity: the SHA-256 of the bytes; each file in one transaction); ``test_points(...)``
and ``flights()`` query it. The command line: ``livesweep campaign add DB FILES...`` and
``livesweep campaign list DB``.
"""

from livesweep.campaign.db import (MIGRATIONS, SCHEMA_VERSION, AddReport, Campaign, FlightRow, TestPointRow,
                                   open)
from livesweep.campaign.scan import ScannedFile, scan_file, sha256_of

__all__ = ["open", "Campaign", "AddReport", "FlightRow", "TestPointRow", "ScannedFile", "scan_file", "sha256_of",
           "MIGRATIONS", "SCHEMA_VERSION"]
