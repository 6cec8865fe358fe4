#!/usr/bin/env python3
"""A TCP listener on 127.0.0.1 for python_subscriber_test.sh (inside its private
network namespace only), standing in for an LCM tcpq:// server. Prints the
port the kernel picked, then "accepted" for each connection, which it holds
open until killed (at most 120 s). Args: MODE

silent: says nothing (a port that accepts and never greets: a typo, a
service that waits for its client to speak first).
greet: answers each connection with an LCM tcpq server's greeting (magic
0x287617fa, protocol version 0x0100, big-endian; LCM's lcm_tcpq.c), then is
silent: a server that never forwards a message.
web: answers with an HTTP error, as a web server would.
greet-once: greets the first connection only (the subscriber's probe), then
is silent: a server that stops answering between the probe and LCM's own
connection (one client at a time, overloaded, or stopped with SIGSTOP).
stall: greets the first connection (the probe) and the second (LCM's own),
sends the second the first part of a message on TISSUE_SIM_STATS (its
header, which says 64 bytes follow, and 8 of them), then is silent, to any
later connection too: a server that hangs mid-message (its kernel still
accepts connections; it answers none). LCM's client reads a message whole,
with a blocking recv().
close: greets every connection, and closes the second (LCM's own) 1 s after
it accepted it, having read what the client sent on it (its subscriptions:
unread data would make the close a reset, not an end of stream): a server
that ends the connection while the client listens."""
import select
import socket
import struct
import sys
import time

GREETING = struct.pack(">II", 0x287617FA, 0x0100)
CHANNEL = b"TISSUE_SIM_STATS"
# A tcpq message: type (1: publish), channel length, channel, data length,
# data (lcm_tcpq.c); here only 8 of the 64 data bytes it announces.
PARTIAL = struct.pack(">II", 1, len(CHANNEL)) + CHANNEL + struct.pack(">I", 64) + bytes(8)
# What each mode sends its 1st, 2nd, ... connection; the last, all the rest.
answers = {"silent": [b""], "greet": [GREETING], "web": [b"HTTP/1.1 400 Bad Request\r\n\r\n"],
           "greet-once": [GREETING, b""], "stall": [GREETING, GREETING + PARTIAL, b""],
           "close": [GREETING]}[sys.argv[1]]
# Which connection (1-based) is closed, and how long after it was accepted.
CLOSE_NTH, CLOSE_AFTER_S = {"close": (2, 1.0)}.get(sys.argv[1], (0, 0.0))
listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
listener.bind(("127.0.0.1", 0))
listener.listen(8)
print(listener.getsockname()[1], flush=True)
held, end = [], time.monotonic() + 120.0
close_at = None  # when the connection CLOSE_NTH is to be closed
while (left := end - time.monotonic()) > 0:
    if close_at is not None and time.monotonic() >= close_at:
        closing = held[CLOSE_NTH - 1]
        closing.setblocking(False)
        while select.select([closing], [], [], 0)[0] and closing.recv(4096):
            pass
        closing.close()
        close_at = None
        print("closed", flush=True)
        continue
    listener.settimeout(left if close_at is None else max(min(left, close_at - time.monotonic()), 0.001))
    try:
        connection, _ = listener.accept()
    except socket.timeout:
        continue
    held.append(connection)
    if len(held) == CLOSE_NTH:
        close_at = time.monotonic() + CLOSE_AFTER_S  # held open: closing would tell the client at once
    answer = answers[min(len(held), len(answers)) - 1]
    if answer:
        connection.sendall(answer)
    print("accepted", flush=True)
