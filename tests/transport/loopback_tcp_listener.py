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
connection (one client at a time, overloaded, or stopped with SIGSTOP)."""
import socket
import struct
import sys
import time

answers = {"silent": b"", "greet": struct.pack(">II", 0x287617FA, 0x0100),
           "web": b"HTTP/1.1 400 Bad Request\r\n\r\n"}
mode = sys.argv[1]
answer = answers["greet" if mode == "greet-once" else mode]
listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
listener.bind(("127.0.0.1", 0))
listener.listen(8)
print(listener.getsockname()[1], flush=True)
held, end = [], time.monotonic() + 120.0
while (left := end - time.monotonic()) > 0:
    listener.settimeout(left)
    try:
        connection, _ = listener.accept()
    except socket.timeout:
        break
    held.append(connection)  # held open: closing would tell the client at once
    if answer:
        connection.sendall(answer)
    if mode == "greet-once":
        answer = b""
    print("accepted", flush=True)
