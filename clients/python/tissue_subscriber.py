#!/usr/bin/env python3
"""Live statistics from a running tissued, over LCM: the template to copy.

Prints one line per sim_stats message (TISSUE_SIM_STATS) and, with --plot,
writes an SVG of tets and real-time factor over time when it stops: after
--seconds, or on SIGINT (Ctrl-C) or SIGTERM. A tcpq:// server is first asked
for LCM's greeting, for at most min(--seconds, 10) s (LCM would wait for
ever), and LCM's own connection after it gets the same limit. Once
listening, a tcpq:// message that stops arriving midway (LCM reads it whole,
blocking) is waited for until --seconds ends, or a stop signal; it is then
dropped, said, and the run ends as after any listening. A standard output
that closes (| head) ends only the printing. Mesh
and haptic messages are counted (TISSUE_SURFACE_MESH, TISSUE_HAPTIC_STATE);
see proto/README.md for every field.

  python3 clients/python/tissue_subscriber.py --seconds 10 --plot stats.svg

Needs the PyPI `lcm` package (pip install lcm==1.5.3) and the Python types
lcm-gen writes at build time (build/release/proto/generated/python; --types
points elsewhere). The daemon publishes when its config says
`publish: {lcm: {enabled: true}}`.
A message that does not decode (another publisher on the channel, a damaged
datagram) is counted and dropped; so is a surface_mesh that decodes but is
not a usable mesh (the checks of the C++ subscriber: 3 coordinates per
vertex, 3 indices per triangle each naming a vertex, finite coordinates and
time, no bytes left over). Non-finite statistics are printed; in the plot a
non-finite value leaves out its own point only (a sample without a finite
time_s leaves out both), and with no finite time_s at all the plot is not
written (exit 3). The plot keeps at most --plot-points points per line
(every other one is dropped when full, so a long run is evenly thinned, not
cut).
The plot is written as the C++ tools write their -o files: to a hidden
temporary file beside it, renamed over it (a failed write leaves an earlier
plot as it was; its permissions are kept; a symbolic link stays a link and
its target is replaced), or in place for a FIFO, a device or a file reached
through /proc (--plot /dev/stdout). A FIFO is given at most 10 s for a
reader to open it, and SIGINT or SIGTERM ends that wait; with no reader the
plot is not written (exit 3, "no reader on the FIFO"). The reader is then
given at most 10 s to take the whole plot (a signal ends that wait too):
one that stopped reading is exit 3, "the FIFO took N of M bytes".
Exit codes: 0 received at least one sim_stats message, 1 none arrived
(said with the time it listened: --seconds, or less after a stop or a lost
connection),
2 bad arguments, missing modules or LCM cannot start at --url (said with the
likely cause: no route for a udpm:// group), 3 statistics arrived but the
plot could not be written.
"""
import argparse
import contextlib
import errno
import io
import math
import os
import select
import signal
import socket
import stat
import struct
import sys
import tempfile
import time

DEFAULT_URL = "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=8388608"
# How long a --plot FIFO is given for a reader to open it, and then for the
# reader to take the whole plot.
FIFO_READER_WAIT_S = 10.0
FIFO_WRITE_WAIT_S = 10.0


def find_types(explicit):
    here = os.path.dirname(os.path.abspath(__file__))
    # Installed (share/tissued/python): the types are beside the script.
    # In a source tree: a build tree's generated ones.
    candidates = [explicit] if explicit else [here] + [
        os.path.join(here, "..", "..", "build", tree, "proto", "generated", "python")
        for tree in ("release", "dev", "asan", "tsan")
    ]
    for c in candidates:
        if c and os.path.isfile(os.path.join(c, "tissue", "sim_stats.py")):
            return os.path.abspath(c)
    return None


def canonical_link_path(path):
    """The canonical directory of `path` joined with its last name (the link
    itself, not followed); "" when the directory does not resolve."""
    directory = os.path.realpath(os.path.dirname(path) or ".")
    if not os.path.isdir(directory):
        return ""
    return os.path.join(directory, os.path.basename(path))


def through_proc(path):
    """Whether `path`, following its symbolic links, passes through /proc: an
    open descriptor's link such as /dev/stdout (-> /proc/self/fd/1), /dev/fd/N
    or /proc/PID/fd/N. Its file is one a process already holds open (a
    shell's `> out`): it is written in place, never renamed over (as root a
    rename would replace /dev/stdout itself). util::through_proc in C++."""
    p = path
    for _ in range(40):  # the kernel's own limit on a chain
        link = canonical_link_path(p)
        if not link:
            return False
        if link.startswith("/proc/"):
            return True
        try:
            if not stat.S_ISLNK(os.lstat(link).st_mode):
                return False
            target = os.readlink(link)
        except OSError:
            return False
        p = target if target.startswith("/") else os.path.join(os.path.dirname(link), target)
    return False


def writes_in_place(st, path):
    """Whether the existing node `path` (os.stat result `st`) is written in
    place rather than replaced: one that is not a regular file (a FIFO, a
    character device such as /dev/null: a rename would put a regular file in
    its place) or a file reached through /proc."""
    return not stat.S_ISREG(st.st_mode) or through_proc(path)


def plot_path_error(path):
    """Why an SVG cannot be written at path, or None: checked before listening,
    so a typo does not cost the whole run. By the rules write_output_file
    follows: a node written in place must be writable; otherwise the
    directory of the file that will be replaced (a symbolic link's target)."""
    try:
        st = os.stat(path)
    except OSError:
        st = None
    if st is not None and stat.S_ISDIR(st.st_mode):
        return "is a directory"
    if st is not None and writes_in_place(st, path):
        return None if os.access(path, os.W_OK) else "is not writable"
    target = os.path.realpath(path) if st is not None and os.path.islink(path) else path
    directory = os.path.dirname(os.path.abspath(target))
    if not os.path.isdir(directory):
        return f"directory {directory} does not exist" if not os.path.exists(directory) \
            else f"{directory} is not a directory"
    if not os.access(directory, os.W_OK | os.X_OK):
        return f"directory {directory} is not writable"
    return None


def open_fifo_for_writing(path, stop):
    """A descriptor writing to the FIFO at path, once a reader has it open.
    Not a blocking open: that waits for a reader for ever, and Python retries
    an open that a signal interrupts (PEP 475), so Ctrl-C could not end it.
    Tried without blocking (ENXIO: no reader yet) every 50 ms for at most
    FIFO_READER_WAIT_S; a signal added to `stop` meanwhile ends the wait.
    OSError(ENXIO) saying which when no reader came."""
    signals_before = len(stop)
    deadline = time.monotonic() + FIFO_READER_WAIT_S
    while True:
        try:
            fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK | os.O_CLOEXEC)
        except OSError as e:
            if e.errno != errno.ENXIO:
                raise
        else:
            return fd  # left non-blocking: write_to_fifo bounds the write
        if len(stop) > signals_before:
            raise OSError(errno.ENXIO, f"no reader on the FIFO (stopped by {signal.Signals(stop[-1]).name})")
        if time.monotonic() >= deadline:
            raise OSError(errno.ENXIO, f"no reader on the FIFO within {FIFO_READER_WAIT_S:g} s")
        time.sleep(0.05)


def write_to_fifo(fd, data, stop):
    """Writes all of `data` to the FIFO open without blocking at `fd`, for at
    most FIFO_WRITE_WAIT_S. A blocking write waited for ever once a reader
    that opened the FIFO stopped reading with the pipe full (64 KiB; a plot
    of a few thousand points is more), and Python retries a write that a
    signal interrupts (PEP 475), so Ctrl-C could not end it either. Written
    as the pipe takes it, waiting in 50 ms slices; a signal added to `stop`
    meanwhile ends the wait. OSError(EAGAIN) saying how much the FIFO took
    when it did not take it all (it then has part of the plot)."""
    signals_before = len(stop)
    deadline = time.monotonic() + FIFO_WRITE_WAIT_S
    view, written = memoryview(data), 0
    while written < len(data):
        try:
            written += os.write(fd, view[written:])
            continue
        except BlockingIOError:
            pass
        took = f"the FIFO took {written} of {len(data)} bytes"
        if len(stop) > signals_before:
            raise OSError(errno.EAGAIN, f"{took} (stopped by {signal.Signals(stop[-1]).name})")
        left = deadline - time.monotonic()
        if left <= 0:
            raise OSError(errno.EAGAIN, f"{took} in {FIFO_WRITE_WAIT_S:g} s (has its reader stopped reading?)")
        select.select([], [fd], [], min(left, 0.05))


def write_output_file(path, text, stop=()):
    """Writes `text` to `path` whole or not at all, by the rules of the C++
    tools' output files (daemon/util/output_file.hpp PendingOutputFile).
    A regular file (or a new name) is written to a hidden temporary file
    beside it, synced and renamed over it: a failure (full disk, file size
    limit) leaves an existing file intact and no temporary file. A symbolic
    link to a regular file stays a link, and the file it names is replaced.
    The replacement keeps the replaced file's permissions (a plot made
    private stays private); a new file is 0666 less the umask. Written in
    place instead, never renamed over: an existing node that is not a regular
    file (a FIFO, a device) and a file reached through /proc (appended to:
    its holder opened it, `>` truncated it already); a FIFO waits for its
    reader as open_fifo_for_writing says and its reader is given at most
    FIFO_WRITE_WAIT_S to take the text (write_to_fifo; `stop`: the signal
    list ends either wait). OSError when it fails."""
    data = text.encode()
    try:
        st = os.stat(path)
    except OSError:
        st = None
    if st is not None and stat.S_ISDIR(st.st_mode):
        raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), path)
    if st is not None and writes_in_place(st, path):
        if stat.S_ISFIFO(st.st_mode):
            fd = open_fifo_for_writing(path, stop)
            try:
                write_to_fifo(fd, data, stop)
            finally:
                os.close(fd)
            return
        fd = os.open(path, os.O_WRONLY | os.O_CLOEXEC | (os.O_APPEND if stat.S_ISREG(st.st_mode) else 0))
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        return
    target = os.path.realpath(path) if st is not None and os.path.islink(path) else path
    directory = os.path.dirname(os.path.abspath(target))
    # Its name cut so that the whole fits the 255 bytes of a name.
    fd, tmp = tempfile.mkstemp(dir=directory, prefix="." + os.path.basename(target)[:200] + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            # mkstemp made it 0600.
            os.fchmod(f.fileno(), stat.S_IMODE(st.st_mode) if st is not None else 0o666 & ~current_umask())
            f.write(data)
            f.flush()
            os.fsync(f.fileno())  # on disk before it replaces anything
        os.replace(tmp, target)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    try:  # the rename itself, durable (best effort: some filesystems refuse it)
        dir_fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)
    except OSError:
        pass


def is_standard_output(path):
    """Whether `path` is the file (or pipe) this process's standard output
    writes to: the "wrote" line then goes to stderr, not into the plot."""
    try:
        out, st = os.fstat(sys.stdout.fileno()), os.stat(path)
    except (OSError, ValueError):
        return False
    return (out.st_dev, out.st_ino) == (st.st_dev, st.st_ino)


class Thinned:
    """At most `limit` points of a stream, evenly spaced: point i is kept while
    i is a multiple of the stride, and the stride doubles (every other kept
    point dropped) whenever the list would exceed the limit. Memory stays
    bounded however long the run."""

    def __init__(self, limit):
        self.limit, self.stride, self.seen, self.points = limit, 1, 0, []

    def add(self, point):
        if self.seen % self.stride == 0:
            self.points.append(point)
            if len(self.points) > self.limit:
                self.points = self.points[::2]
                self.stride *= 2
        self.seen += 1


def fraction(x, lo, hi):
    """Where x lies between lo and hi, 0 .. 1 (0 when they are equal). Halves
    first: hi - lo of two finite doubles can overflow to inf (times of -1e308
    and 1e308 from a foreign publisher), and inf / inf is NaN; half of each
    cannot."""
    span = hi / 2 - lo / 2
    return (x / 2 - lo / 2) / span if span > 0 else 0.0


def write_svg(path, samples, stop=()):
    """A two-panel line plot (tets, real-time factor vs sim time), no matplotlib,
    written by write_output_file's rules: a failure (full disk, file size
    limit) leaves an existing plot intact. False when there is nothing to plot
    (no sample with a finite time); OSError when writing fails. `stop`: the
    signal list, which ends the wait for a FIFO's reader."""
    width, height, pad = 640, 400, 50
    # A point needs a finite time; a NaN or infinite value leaves out its own
    # point only (a NaN would break the polyline), so the tets of a sample
    # whose real-time factor is not yet measured are still drawn.
    samples = [s for s in samples if math.isfinite(s[0])]
    if not samples:
        return False
    t = [s[0] for s in samples]
    series = [("tets", [s[1] for s in samples], "#1f77b4"), ("real-time factor", [s[2] for s in samples], "#d62728")]
    t0, t1 = min(t), max(t)
    panel_h = (height - 3 * pad) / 2
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}">',
           f'<rect width="{width}" height="{height}" fill="white"/>']
    for i, (name, values, colour) in enumerate(series):
        top = pad + i * (panel_h + pad)
        out.append(f'<rect x="{pad}" y="{top}" width="{width - 2 * pad}" height="{panel_h}" fill="none" stroke="#888"/>')
        finite = [(x, v) for x, v in zip(t, values) if math.isfinite(v)]
        if not finite:
            out.append(f'<text x="{pad}" y="{top - 6}" font-size="12">{name}: no finite values</text>')
            continue
        lo, hi = min(v for _, v in finite), max(v for _, v in finite)
        points = " ".join(f"{pad + fraction(x, t0, t1) * (width - 2 * pad):.1f},"
                          f"{top + panel_h - fraction(v, lo, hi) * panel_h:.1f}"
                          for x, v in finite)
        out.append(f'<polyline points="{points}" fill="none" stroke="{colour}" stroke-width="1.5"/>')
        out.append(f'<text x="{pad}" y="{top - 6}" font-size="12">{name}: {lo:g} .. {hi:g}</text>')
    out.append(f'<text x="{pad}" y="{height - 12}" font-size="12">sim time {t0:.6g} .. {t1:.6g} s</text>')
    out.append("</svg>")
    write_output_file(path, "\n".join(out) + "\n", stop)
    return True


def current_umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def udpm_group(url):
    """The multicast group of a udpm:// URL as a 32-bit number, or None when the
    URL does not start with a dotted IPv4 multicast address (the C++
    daemon/util/lcm_url.cpp udpm_group: four octets of 1 to 3 digits, no
    leading zero, which inet_aton would read as octal)."""
    if not url.startswith("udpm://"):
        return None
    address = url[len("udpm://"):].split("?", 1)[0]
    octets = address.rsplit(":", 1)[0].split(".")
    if len(octets) != 4 or not all(o.isdigit() and o.isascii() and len(o) <= 3 and (o == "0" or o[0] != "0")
                                   and int(o) <= 255 for o in octets):
        return None
    group = 0
    for o in octets:
        group = group << 8 | int(o)
    return group if group >> 28 == 0xE else None


def has_route_to(group, proc_net_route):
    """Whether the IPv4 routing table (the text of /proc/net/route) has an up
    route covering `group`: a default route or one whose destination and mask
    contain it. The table prints each address as the 32-bit word of its
    network-order bytes read in this machine's order, so the group is put in
    the same form."""
    raw = int.from_bytes(group.to_bytes(4, "big"), sys.byteorder)
    for line in proc_net_route.splitlines()[1:]:
        fields = line.split()
        if len(fields) < 8:
            continue
        try:
            destination, flags, mask = int(fields[1], 16), int(fields[3], 16), int(fields[7], 16)
        except ValueError:
            continue
        if flags & 0x1 and raw & mask == destination:  # RTF_UP
            return True
    return False


def lcm_start_failure(url):
    """Why lcm.LCM(url) failed, as far as can be told from outside (LCM prints
    its own reason on stderr; the exception says only "Couldn't create LCM").
    The wording of the C++ clients (daemon/util/lcm_url.cpp lcm_start_failure)."""
    group = udpm_group(url)
    if group is not None:
        try:
            with open("/proc/net/route") as f:
                table = f.read()
        except OSError:
            table = None
        if table is not None and not has_route_to(group, table):
            dotted = ".".join(str(group >> shift & 0xFF) for shift in (24, 16, 8, 0))
            return (f"cannot start LCM: no route covers its multicast group {dotted} "
                    "(add one, e.g. `ip route add 224.0.0.0/4 dev lo` for this host only)")
    return "cannot start LCM (LCM's own message above says why)"


TCPQ_GREETING_WAIT_S = 10.0  # at most; less when --seconds is shorter (the C++ clients' wait)
TCPQ_MAGIC_CLIENT, TCPQ_MAGIC_SERVER, TCPQ_VERSION = 0x287617FB, 0x287617FA, 0x0100  # LCM's lcm_tcpq.c


def tcpq_server_problem(url, timeout_s, stop):
    """Whether a tcpq:// URL's server answers LCM's greeting within timeout_s:
    None when it does (or the URL is not tcpq://), else why not. LCM's own
    client sends its magic number and protocol version and then waits for the
    server's (8 bytes, big-endian) inside lcm.LCM() with no time limit, so a
    port that accepts and says nothing hung the subscriber past --seconds. The
    probe of the C++ clients (daemon/util/lcm_url.cpp tcpq_server_problem),
    with LCM's own defaults for a missing host (127.0.0.1) or port (7700). It
    waits in slices and gives up early once `stop` (the signal list) fills."""
    if not url.startswith("tcpq://"):
        return None
    host, _, port = url[len("tcpq://"):].split("?", 1)[0].partition(":")  # LCM splits at the first ':'
    host, port = host or "127.0.0.1", port or "7700"
    if not (port.isascii() and port.isdigit() and len(port) <= 5 and 1 <= int(port) <= 65535):
        return "the port must be in [1, 65535]"
    try:
        address = socket.getaddrinfo(host, int(port), socket.AF_INET, socket.SOCK_STREAM)[0][4]
    except (OSError, IndexError):
        return f"cannot resolve '{host}'"
    deadline = time.monotonic() + timeout_s

    def ready(s, writing):
        while not stop and (left := deadline - time.monotonic()) > 0:
            r, w, _ = select.select([] if writing else [s], [s] if writing else [], [], min(left, 0.1))
            if r or w:
                return True
        return False

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setblocking(False)
        err = s.connect_ex(address)
        if err not in (0, errno.EINPROGRESS):
            return f"cannot connect: {os.strerror(err)}"
        if not ready(s, True):
            return f"no connection within {timeout_s:g} s"
        err = s.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR)
        if err:
            return f"cannot connect: {os.strerror(err)}"
        try:
            s.sendall(struct.pack(">II", TCPQ_MAGIC_CLIENT, TCPQ_VERSION))  # 8 bytes: a fresh socket takes them
            reply = b""
            while len(reply) < 8 and ready(s, False):
                chunk = s.recv(8 - len(reply))
                if not chunk:
                    break
                reply += chunk
        except OSError as e:
            return f"cannot greet the server: {e.strerror or e}"
    if len(reply) < 8:
        return f"the server did not answer LCM's greeting within {timeout_s:g} s (is it an LCM tcpq server?)"
    if struct.unpack(">I", reply[:4])[0] != TCPQ_MAGIC_SERVER:
        return "the server's answer is not LCM's (is it an LCM tcpq server?)"
    return None


@contextlib.contextmanager
def lost_lcm_teardown():
    """Around dropping the last reference to an LCM whose tcpq:// connection
    is lost: its teardown then does not wait for the server. LCM's teardown
    unsubscribes each channel, and with no socket that reconnects first: a
    blocking connect() and a wait for the greeting with no time limit, for
    ever against a server that hung (its kernel still accepts). Here under
    SIGALRM every 50 ms (LCM gives up on EINTR, as in its first connection in
    main) and with standard error silenced: those attempts' own lines ("LCM
    tcpq: connecting...", "Unable to connect to server") would follow the
    one that says what happened."""
    sys.stderr.flush()
    saved_stderr = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    previous = signal.signal(signal.SIGALRM, lambda signum, frame: None)
    signal.setitimer(signal.ITIMER_REAL, 0.05, 0.05)
    try:
        os.dup2(devnull, 2)
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
        os.dup2(saved_stderr, 2)
        os.close(saved_stderr)
        os.close(devnull)


def mesh_error(m, left_bytes):
    """Why the decoded surface_mesh `m`, followed by `left_bytes` undecoded
    bytes, is not a usable mesh: (reason, text), or None. The rules of the
    C++ subscriber (daemon/transport/lcm_subscriber.cpp lcm_mesh_layout_error,
    mesh_subscriber.cpp frame_from_mesh_arrays), with its reason names:
    lcm-gen's Python decoder reads each array by its own count field and
    ignores what follows, so decoding alone checks neither the 3·V / 3·T
    rules, the indices, the values nor trailing bytes."""
    if left_bytes:
        return "size", f"{left_bytes} byte(s) after the message"
    nv, nt = m.vertex_count, m.triangle_count
    if nv < 0 or m.vertex_coordinate_count != 3 * nv:
        return "size", (f"vertex_count {nv} with vertex_coordinate_count {m.vertex_coordinate_count} "
                        "(must be 3 · vertex_count)")
    if nt < 0 or m.triangle_index_count != 3 * nt:
        return "size", (f"triangle_count {nt} with triangle_index_count {m.triangle_index_count} "
                        "(must be 3 · triangle_count)")
    if not math.isfinite(m.time_s):
        return "non_finite", "time_s is not finite"
    # One sum instead of a call per value: float32 values cannot overflow a
    # double sum, so it is finite exactly when every coordinate is.
    if not math.isfinite(sum(m.vertex_m)):
        i = next(k for k, x in enumerate(m.vertex_m) if not math.isfinite(x)) // 3
        return "non_finite", f"vertex {i} has a non-finite coordinate"
    tv = m.triangle_vertex
    if tv and (min(tv) < 0 or max(tv) >= nv):
        k = next(k for k, v in enumerate(tv) if not 0 <= v < nv)
        return "index", f"triangle {k // 3} uses vertex {tv[k]} of {nv}"
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--url", default=DEFAULT_URL, help="LCM URL (default: %(default)s)")
    ap.add_argument("--types", help="directory holding the generated 'tissue' Python package")
    ap.add_argument("--seconds", type=float, default=10.0, help="how long to listen")
    ap.add_argument("--plot", help="write an SVG of the statistics here when done")
    ap.add_argument("--plot-points", type=int, default=10000,
                    help="at most this many points per plotted line (default: %(default)s)")
    args = ap.parse_args()
    if not args.seconds > 0:
        print("tissue_subscriber: --seconds must be > 0", file=sys.stderr)
        return 2
    if args.plot_points < 2:
        print(f"tissue_subscriber: --plot-points {args.plot_points}: must be at least 2", file=sys.stderr)
        return 2
    if args.plot is not None:
        why = plot_path_error(args.plot) if args.plot else "is empty"
        if why:
            print(f"tissue_subscriber: --plot {args.plot}: {why}", file=sys.stderr)
            return 2
    try:
        import lcm
    except ImportError:
        print("tissue_subscriber: the 'lcm' module is missing: pip install lcm==1.5.3", file=sys.stderr)
        return 2
    types = find_types(args.types)
    if not types:
        print("tissue_subscriber: no generated types (build the project, or pass --types DIR)", file=sys.stderr)
        return 2
    sys.path.insert(0, types)
    from tissue import haptic_state, sim_stats, surface_mesh

    # SIGINT and SIGTERM end the listening early; the summary and the plot
    # still follow. Installed before LCM starts: a tcpq:// server's greeting
    # is waited for before listening, and Ctrl-C there is a stop too, not a
    # KeyboardInterrupt traceback. (A SIGINT the parent ignores, as a shell
    # does for a background job, stays ignored.)
    stop = []
    reading = []  # non-empty while lc.handle() reads a tcpq:// message (the listening loop)

    def on_signal(signum, frame):
        stop.append(signum)
        if reading:
            # Python runs this between its own instructions, never inside
            # LCM's blocking recv() (a signal there makes it fail at once,
            # EINTR): the signal landed after the loop last looked at `stop`
            # and before LCM's recv(), which would wait for a stalled
            # message's rest until the deadline alarm. An alarm 50 ms from
            # now (repeated) interrupts it instead.
            signal.setitimer(signal.ITIMER_REAL, 0.05, 0.05)

    signal.signal(signal.SIGTERM, on_signal)
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
        signal.signal(signal.SIGINT, on_signal)
    # LCM's tcpq client waits for its server's greeting with no time limit
    # (--seconds would never start): the greeting is asked for first.
    why = tcpq_server_problem(args.url, min(args.seconds, TCPQ_GREETING_WAIT_S), stop)
    if stop:
        print(f"tissue_subscriber: stopped before listening at {args.url}; no sim_stats", file=sys.stderr)
        return 1
    if why:
        print(f"tissue_subscriber: --url {args.url}: {why}", file=sys.stderr)
        return 2
    # LCM's own tcpq connection, made after the probe, waits for the greeting
    # without a time limit too: a server that answered the probe and then
    # stops answering (one client at a time, overloaded, paused) held
    # lcm.LCM() for ever. It gets the probe's limit: from then on SIGALRM
    # every 50 ms interrupts its connect() or recv() (Python installs its
    # handlers without SA_RESTART, and LCM gives up on EINTR, leaving no
    # socket), as SIGINT and SIGTERM do; repeated, so an alarm that lands
    # just before LCM enters recv() is followed by another.
    timed_out = []
    connect_limit_s = min(args.seconds, TCPQ_GREETING_WAIT_S)
    tcpq = args.url.startswith("tcpq://")
    if tcpq:
        signal.signal(signal.SIGALRM, lambda signum, frame: timed_out.append(signum))
        signal.setitimer(signal.ITIMER_REAL, connect_limit_s, 0.05)
    try:
        try:
            lc = lcm.LCM(args.url)
        finally:
            if tcpq:
                signal.setitimer(signal.ITIMER_REAL, 0)
        # A tcpq server that went away since it greeted leaves LCM without a
        # socket (fileno -1), which select() would refuse.
        if lc.fileno() < 0:
            raise RuntimeError("no socket")
    except (IOError, RuntimeError):  # its text is only "Couldn't create LCM"
        if stop:
            print(f"tissue_subscriber: stopped before listening at {args.url}; no sim_stats", file=sys.stderr)
            return 1
        if timed_out:
            print(f"tissue_subscriber: --url {args.url}: LCM's own connection got no greeting within "
                  f"{connect_limit_s:g} s (the server answered the probe before it; is it still serving?)",
                  file=sys.stderr)
            return 2
        print(f"tissue_subscriber: --url {args.url}: {lcm_start_failure(args.url)}", file=sys.stderr)
        return 2
    stdout_closed = []

    def say(line):
        """One line on standard output, unless it has closed (`| head`): then
        nothing more is printed, and listening and the plot go on."""
        if stdout_closed:
            return
        try:
            print(line, flush=True)
        except BrokenPipeError:
            stdout_closed.append(True)
            # What the failed print left buffered would fail again at exit
            # ("Exception ignored ... BrokenPipeError", exit 120): standard
            # output becomes /dev/null (the way the Python docs give).
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())

    # Decided now: a closed standard output becomes /dev/null (say), which a
    # --plot /dev/stdout would then silently write to.
    plot_is_stdout = args.plot is not None and is_standard_output(args.plot)
    # Only what the plot needs is kept, and at most --plot-points of it.
    plot = Thinned(args.plot_points) if args.plot else None
    counts = {"stats": 0, "mesh": 0, "haptic": 0}
    undecodable, bad_meshes = {}, {}

    def decoded(kind, channel, data):
        """(the message, how many bytes followed it), or (None, 0) when it does
        not decode (counted; the first one per channel said)."""
        buf = io.BytesIO(data)
        try:
            m = kind.decode(buf)
        except Exception as e:  # LCM's decoders raise ValueError, struct.error, ...
            undecodable[channel] = undecodable.get(channel, 0) + 1
            if undecodable[channel] == 1:
                print(f"tissue_subscriber: dropped a {len(data)}-byte message on {channel} that is not a "
                      f"{kind.__name__}: {e}", file=sys.stderr)
            return None, 0
        return m, len(data) - buf.tell()

    def on_stats(channel, data):
        m, _ = decoded(sim_stats, channel, data)
        if m is None:
            return
        counts["stats"] += 1
        sample = (m.time_s, m.tet_count, m.real_time_factor)
        if plot is not None and math.isfinite(m.time_s):  # write_svg leaves out each non-finite value alone
            plot.add(sample)
        say(f"t {m.time_s:8.3f} s  nodes {m.node_count:6d}  tets {m.tet_count:7d}  springs {m.spring_count:7d}  "
            f"refines {m.refine_count:6d}  merges {m.merge_count:6d}  rtf {m.real_time_factor:5.2f}  "
            f"E {m.kinetic_energy_J + m.elastic_energy_J:.3e} J  "
            f"(meshes {counts['mesh']}, haptic states {counts['haptic']})")

    def on_mesh(channel, data):
        m, left_bytes = decoded(surface_mesh, channel, data)
        if m is None:
            return
        error = mesh_error(m, left_bytes)
        if error is None:
            counts["mesh"] += 1
            return
        reason, text = error
        bad_meshes[reason] = bad_meshes.get(reason, 0) + 1
        if bad_meshes[reason] == 1:
            print(f"tissue_subscriber: dropped a malformed surface_mesh on {channel} ({reason}): {text}",
                  file=sys.stderr)

    def on_haptic(channel, data):
        if decoded(haptic_state, channel, data)[0] is not None:
            counts["haptic"] += 1

    lc.subscribe("TISSUE_SIM_STATS", on_stats)
    lc.subscribe("TISSUE_SURFACE_MESH", on_mesh)
    lc.subscribe("TISSUE_HAPTIC_STATE", on_haptic)
    started = time.monotonic()
    end = started + args.seconds
    lost = None  # why LCM's connection ended before --seconds did, or None
    cut_short = None  # why listening ended before --seconds did, or None
    while not stop and (left := end - time.monotonic()) > 0:
        ready, _, _ = select.select([lc.fileno()], [], [], min(left, 0.1))
        if not ready or stop:
            continue
        # tcpq:// is a stream: once its first bytes are there, handle() reads
        # the whole message with blocking recv()s, and a server that stops
        # in the middle of one held it (and the subscriber) for ever. The read
        # is given until --seconds ends: from then SIGALRM every 50 ms
        # interrupts it, as it does LCM's connect() above (repeated for the
        # same reason). Never sooner: LCM drops its connection on any
        # interrupted recv(), so a read still going well must not be cut.
        # SIGINT and SIGTERM interrupt it too (Python installs its handlers
        # without SA_RESTART); one whose handler runs before the read starts
        # is seen by the `stop` check below or, once `reading` is set, arms
        # that alarm for 50 ms from then (on_signal). Left to the deadline:
        # only a signal that lands where no Python code runs, entering
        # handle() or between LCM's recv()s (microseconds a message).
        if tcpq:
            began = time.monotonic()
            signal.setitimer(signal.ITIMER_REAL, max(end - began, 0.001), 0.05)
            reading.append(True)
        try:
            if stop:  # landed since select() returned, before `reading` was set
                continue
            lc.handle()
        except OSError:  # only "lcm_handle() returned -1": our callbacks catch their own
            # LCM has closed its socket (fileno() is now -1, which select()
            # refuses) and would reconnect, without a time limit, on the
            # next handle(): listening ends here. Whether a stop signal
            # interrupted it: its Python handler has not run yet (it runs
            # at some later instruction); pthread_sigmask runs pending
            # handlers before it returns (PyErr_CheckSignals), changing no
            # mask here. The deadline is read from the clock, not from the
            # signal: SIGALRM also comes before it when on_signal armed the
            # 50 ms alarm for a stop, and that case is the `stop` one first.
            signal.pthread_sigmask(signal.SIG_BLOCK, [])
            if stop:
                lost = (f"stopped by {signal.Signals(stop[-1]).name} in the middle of a message from the server; "
                        "it is dropped")
            elif tcpq and time.monotonic() >= end:
                lost = (f"a message from the server was still incomplete when --seconds ended "
                        f"({time.monotonic() - began:.1f} s after it began; has the server stalled?); it is dropped")
            else:
                cause = "the server closed it, or a read failed" if tcpq else "lcm_handle() failed"
                lost = (f"LCM lost its connection {time.monotonic() - started:.1f} s into --seconds "
                        f"({cause}); listening ended there")
                cut_short = "LCM lost its connection"
            break
        finally:
            if tcpq:
                reading.clear()  # first: a stop from here on arms no alarm
                signal.setitimer(signal.ITIMER_REAL, 0)
    # The time it listened, for a summary after a stop or a lost connection:
    # not the --seconds asked.
    ended_at = time.monotonic()
    listened_s = min(ended_at, end) - started
    if stop and cut_short is None and ended_at < end:
        cut_short = f"stopped by {signal.Signals(stop[-1]).name}"
    if lost:
        print(f"tissue_subscriber: --url {args.url}: {lost}", file=sys.stderr, flush=True)
        if tcpq:
            with lost_lcm_teardown():
                lc = None  # the last reference: LCM is destroyed here
    for channel, n in sorted(undecodable.items()):
        print(f"tissue_subscriber: {n} undecodable message(s) dropped on {channel}", file=sys.stderr)
    if bad_meshes:
        reasons = ", ".join(f"{reason} {n}" for reason, n in sorted(bad_meshes.items()))
        print(f"tissue_subscriber: {sum(bad_meshes.values())} malformed surface_mesh message(s) dropped ({reasons})",
              file=sys.stderr)
    if not counts["stats"]:
        if cut_short is None:
            print(f"tissue_subscriber: no sim_stats at {args.url} in {args.seconds:g} s (is publish.lcm.enabled on?)",
                  file=sys.stderr)
        else:
            hint = "; is publish.lcm.enabled on?" if stop else ""  # not for a lost connection
            print(f"tissue_subscriber: no sim_stats at {args.url} in {listened_s:.1f} s "
                  f"({cut_short} before --seconds {args.seconds:g} ended{hint})", file=sys.stderr)
        return 1
    if plot is not None:
        if stdout_closed and plot_is_stdout:
            print(f"tissue_subscriber: cannot write {args.plot}: standard output has closed", file=sys.stderr)
            return 3
        try:
            if write_svg(args.plot, plot.points, stop):
                summary = f"wrote {args.plot} ({len(plot.points)} of {plot.seen} points)"
                if plot_is_stdout:  # not after the plot on standard output (--plot /dev/stdout)
                    print(summary, file=sys.stderr)
                else:
                    say(summary)
            else:
                # The plot asked for is not there (an earlier one stays): 3, as
                # for any plot that cannot be written, not 0.
                print(f"tissue_subscriber: cannot write {args.plot}: nothing to plot: none of the {counts['stats']} "
                      "sim_stats received has a finite time_s", file=sys.stderr)
                return 3
        except OSError as e:
            print(f"tissue_subscriber: cannot write {args.plot}: {e.strerror or e}", file=sys.stderr)
            return 3
    return 0


if __name__ == "__main__":
    sys.exit(main())
