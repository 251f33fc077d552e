"""python-can's `ReaderWriterTest` (test/logformats_test.py) for the bench's ".mcap" format.

Declared as python-can declares its own formats (TestBlfFileFormat etc.): one subclass whose
`_setup_instance` names the writer, the reader and what the format keeps. The runner copies this file
into python-can's `test/` package, so the relative imports below resolve as in logformats_test.py.
"""

import unittest

import can

from bench.log.canio import MCAPReader, MCAPWriter

from . import logformats_test

# python-can deletes the name ReaderWriterTest at the end of logformats_test.py (so it is never run on its
# own); its format classes still derive from it. Not bound to a module name here either, for the same reason.


class TestMcapFileFormat(logformats_test.TestBlfFileFormat.__bases__[0]):
    """Tests bench.log.canio.MCAPWriter and bench.log.canio.MCAPReader."""

    def _setup_instance(self):
        super()._setup_instance_helper(
            MCAPWriter,
            MCAPReader,
            binary_file=True,
            check_remote_frames=True,
            check_error_frames=True,
            check_fd=True,
            check_comments=False,           # the writer has no log_event(): the run log has no comment records
            test_append=False,              # an MCAP file cannot be appended to (MCAPWriter raises ValueError)
            allowed_timestamp_delta=1e-9,   # log times are integer nanoseconds
            preserves_channel=True,
            adds_default_channel=None,
        )


class TestMcapFileExtension(unittest.TestCase):
    """python-can's ReaderWriterExtensionTest for ".mcap": can.Logger and can.LogReader pick the bench's
    classes for every case variant of the suffix."""

    _get_suffix_case_variants = logformats_test.ReaderWriterExtensionTest._get_suffix_case_variants
    _test_extension = logformats_test.ReaderWriterExtensionTest._test_extension

    def test_extension_matching_mcap(self):
        # python-can loads format plugins on the first Logger/LogReader; _test_extension checks nothing for a
        # suffix not yet in these tables, so load them now and make sure the bench's classes are there.
        can.io.logger._update_writer_plugins()
        can.io.player._update_reader_plugins()
        assert can.io.MESSAGE_WRITERS.get(".mcap") is MCAPWriter
        assert can.io.MESSAGE_READERS.get(".mcap") is MCAPReader
        self._test_extension(".mcap")
