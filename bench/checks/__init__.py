"""Checks of the frames and of the bench itself: the monitor, the steps' verdicts, the bench's timing, findings."""
