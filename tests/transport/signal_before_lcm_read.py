#!/usr/bin/env python3
"""Runs tissue_subscriber.py with a stop signal that lands between its
select() (LCM's socket is readable) and LCM's read, for
python_subscriber_test.sh (inside its private network namespace only).
Args: SUBSCRIBER [ITS ARGUMENTS...]

The first lc.handle() sends SIGTERM to this process and only then lets LCM
read: the subscriber's Python signal handler runs in between (Python runs it
at its next instruction), after the subscriber last looked at its stop list
and before LCM's blocking recv(), the window a real signal can land in.
Against a server that stalls mid-message, that recv() waits for the rest
unless the subscriber interrupts it."""
import os
import runpy
import signal
import sys

import lcm


class SignalledBeforeFirstRead(lcm.LCM):
    signalled = False

    def handle(self):
        if not SignalledBeforeFirstRead.signalled:
            SignalledBeforeFirstRead.signalled = True
            os.kill(os.getpid(), signal.SIGTERM)
        return super().handle()


lcm.LCM = SignalledBeforeFirstRead  # the subscriber's own `import lcm` finds this module
sys.argv = sys.argv[1:]
runpy.run_path(sys.argv[0], run_name="__main__")
