#!/bin/sh
# End to end in a private network namespace (run through in_netns.sh): the
# daemon publishes over LCM, the Python template subscriber prints stats
# and writes its SVG plot; then, against foreign_lcm_publisher.py alone, the
# --plot errors, a plot that cannot be written, the plot's point bound and
# stopping on a signal. Args: TISSUED_BINARY SOURCE_DIR PYTHON_TYPES_DIR
set -eu
tissued="$1"; src="$2"; types="$3"
here="$(dirname "$0")"
subscriber="$src/clients/python/tissue_subscriber.py"
if ! python3 -c 'import lcm' 2>/dev/null; then
  echo "python_subscriber_test: python3 has no 'lcm' module (scripts/install-deps.sh installs it); skipped" >&2
  exit 77
fi
work="$(mktemp -d)"
stream=""
helpers=""  # background listeners and publishers, killed at exit
trap '[ -z "$stream" ] || kill "$stream" 2>/dev/null; for h in $helpers; do kill "$h" 2>/dev/null || :; done; rm -rf "$work"' EXIT
"$tissued" --config "$src/config/tissued.yaml" --duration 4 \
  --set "control.unix_socket_path=$work/c.sock" --set "state_dir=$work" \
  --set publish.lcm.enabled=true --set realtime.sched_fifo=false >"$work/daemon.log" 2>&1 &
daemon=$!
# A foreign publisher on the same channels (this private namespace): one
# datagram that is not a mesh, five meshes that decode but are malformed,
# and statistics with a NaN real-time factor. The subscriber drops the
# first six (saying so), prints the last and keeps it out of the plot.
python3 "$here/foreign_lcm_publisher.py" "$types" &
foreign=$!
python3 "$subscriber" --types "$types" --seconds 3 --plot "$work/stats.svg" >"$work/sub.log" 2>"$work/sub.err"
wait "$foreign"
wait "$daemon"
grep -q 'dropped a 18-byte message on TISSUE_SURFACE_MESH that is not a surface_mesh' "$work/sub.err" ||
  { echo "the foreign message was not reported"; cat "$work/sub.err"; exit 1; }
grep -q '1 undecodable message(s) dropped on TISSUE_SURFACE_MESH' "$work/sub.err" || { cat "$work/sub.err"; exit 1; }
# Decoding alone accepted these (it reads each array by its own count and
# ignores trailing bytes): the C++ subscriber's checks drop them.
grep -q '5 malformed surface_mesh message(s) dropped (index 2, non_finite 1, size 2)' "$work/sub.err" ||
  { echo "the malformed meshes were not dropped"; cat "$work/sub.err"; exit 1; }
grep -q 'dropped a malformed surface_mesh on TISSUE_SURFACE_MESH (index): triangle 0 uses vertex -1 of 3' \
  "$work/sub.err" || { cat "$work/sub.err"; exit 1; }
grep -q 'rtf   nan' "$work/sub.log" || { echo "the NaN statistics were not printed"; cat "$work/sub.log"; exit 1; }
if grep -qi 'nan' "$work/stats.svg"; then echo "NaN in the plot"; exit 1; fi
lines="$(grep -c '^t ' "$work/sub.log")"
echo "subscriber printed $lines stats lines"
[ "$lines" -ge 5 ] || { cat "$work/sub.log" "$work/daemon.log"; exit 1; }
grep -q '<polyline' "$work/stats.svg" || { echo "no plot"; exit 1; }
# Meshes and haptic states arrived and decoded.
grep '^t ' "$work/sub.log" | tail -1 | grep -q 'meshes [1-9][0-9]*, haptic states [1-9]' || { tail -3 "$work/sub.log"; exit 1; }

fail() { echo "python_subscriber_test: $*"; exit 1; }
# FILE: how many statistics lines FILE holds. 0 while it does not exist: a
# background subscriber's `>FILE` is opened by its shell, which may not have
# run yet (grep said "No such file or directory" then, and `[ "" -gt N ]`
# "Illegal number"; noise, not a failure, but noise that hides real ones).
stats_lines() { if [ -f "$1" ]; then grep -c '^t ' "$1" || :; else echo 0; fi; }
no_traceback() { if grep -q Traceback "$1"; then cat "$1"; fail "a traceback in $1"; fi; }
# FILE: the N s of the "no sim_stats at URL in N s (...)" summary in FILE.
summary_s() { sed -n 's/.*: no sim_stats at .* in \([0-9.]*\) s (.*/\1/p' "$1" | head -1; }
# X LO HI: whether the number X lies in [LO, HI] (false for an empty X).
within() { awk -v x="$1" -v lo="$2" -v hi="$3" 'BEGIN { exit !(x != "" && x + 0 >= lo && x + 0 <= hi) }'; }
# PID SECONDS MESSAGE: waits for a signalled process to end; still running
# after SECONDS, it is killed and the test fails with MESSAGE.
ends_within() {
  polls=0
  while kill -0 "$1" 2>/dev/null; do
    polls=$((polls + 1))
    [ "$polls" -le $(($2 * 10)) ] || { kill -KILL "$1"; fail "$3"; }
    sleep 0.1
  done
}

# --plot is checked before listening: a missing directory or a directory is
# a bad argument (2), named with the reason, without a traceback.
rc=0
python3 "$subscriber" --types "$types" --seconds 0.5 --plot "$work/nodir/s.svg" >"$work/nodir.log" 2>&1 || rc=$?
[ "$rc" -eq 2 ] || { cat "$work/nodir.log"; fail "--plot in a missing directory: exit $rc, expected 2"; }
grep -q -- "--plot $work/nodir/s.svg: directory $work/nodir does not exist" "$work/nodir.log" ||
  { cat "$work/nodir.log"; fail "--plot in a missing directory: no reason"; }
no_traceback "$work/nodir.log"
rc=0
python3 "$subscriber" --types "$types" --seconds 0.5 --plot "$work" >"$work/isdir.log" 2>&1 || rc=$?
[ "$rc" -eq 2 ] || { cat "$work/isdir.log"; fail "--plot at a directory: exit $rc, expected 2"; }
grep -q -- "--plot $work: is a directory" "$work/isdir.log" || { cat "$work/isdir.log"; fail "--plot at a directory"; }

# --seconds that is not > 0 and --plot-points under 2 are bad arguments (2),
# said before listening.
for seconds in 0 -1 nan; do
  rc=0
  python3 "$subscriber" --types "$types" --seconds "$seconds" >"$work/seconds.log" 2>&1 || rc=$?
  [ "$rc" -eq 2 ] || { cat "$work/seconds.log"; fail "--seconds $seconds: exit $rc, expected 2"; }
  grep -q -- "--seconds must be > 0" "$work/seconds.log" || { cat "$work/seconds.log"; fail "--seconds $seconds: no reason"; }
  no_traceback "$work/seconds.log"
done
rc=0
python3 "$subscriber" --types "$types" --seconds 0.5 --plot-points 1 >"$work/points.log" 2>&1 || rc=$?
[ "$rc" -eq 2 ] || { cat "$work/points.log"; fail "--plot-points 1: exit $rc, expected 2"; }
grep -q -- "--plot-points 1: must be at least 2" "$work/points.log" || { cat "$work/points.log"; fail "--plot-points 1"; }

# Nothing published (the daemon and the foreign publisher are gone): exit 1,
# said with the URL, and no plot.
rc=0
python3 "$subscriber" --types "$types" --seconds 0.5 --plot "$work/none.svg" >"$work/none.log" 2>&1 || rc=$?
[ "$rc" -eq 1 ] || { cat "$work/none.log"; fail "no statistics: exit $rc, expected 1"; }
grep -q "no sim_stats at udpm://239.255.76.67:7667?ttl=0&recv_buf_size=8388608 in 0.5 s" "$work/none.log" ||
  { cat "$work/none.log"; fail "no statistics: not said"; }
[ ! -e "$work/none.svg" ] || fail "a plot without statistics"
no_traceback "$work/none.log"

# LCM cannot start: exit 2 naming --url and why. In a network namespace of
# its own (nested in this one; nothing leaves it) no route covers the
# multicast group; a scheme LCM does not know is left to LCM's own message.
if unshare -n true 2>/dev/null; then
  rc=0
  unshare -n sh -c 'ip link set lo up && exec "$@"' noroute python3 "$subscriber" --types "$types" --seconds 0.5 \
    >"$work/noroute.log" 2>&1 || rc=$?
  [ "$rc" -eq 2 ] || { cat "$work/noroute.log"; fail "no multicast route: exit $rc, expected 2"; }
  grep -q -- "--url udpm://239.255.76.67:7667?ttl=0&recv_buf_size=8388608: cannot start LCM: no route covers its multicast group 239.255.76.67 (add one, e.g. \`ip route add 224.0.0.0/4 dev lo\` for this host only)" \
    "$work/noroute.log" || { cat "$work/noroute.log"; fail "no multicast route: the cause is not said"; }
  no_traceback "$work/noroute.log"
else
  echo "python_subscriber_test: no nested network namespace here; the no-route case is not run"
fi
rc=0
python3 "$subscriber" --types "$types" --seconds 0.5 --url "nosuch://x" >"$work/scheme.log" 2>&1 || rc=$?
[ "$rc" -eq 2 ] || { cat "$work/scheme.log"; fail "an unknown scheme: exit $rc, expected 2"; }
grep -q -- "--url nosuch://x: cannot start LCM (LCM's own message above says why)" "$work/scheme.log" ||
  { cat "$work/scheme.log"; fail "an unknown scheme: --url not named"; }

# A tcpq:// server that accepts and never greets: LCM's client waits for the
# greeting without a time limit. The subscriber gives up after
# min(--seconds, 10) s: exit 2 naming --url and why. A server that greets is
# listened to for --seconds (nothing arrives: exit 1); one whose answer is not
# LCM's is exit 2.
listen() {  # MODE: starts a loopback_tcp_listener.py, sets $port and $listener_log
  listener_log="$work/listener-$1.log"
  rm -f "$listener_log"  # a MODE's second listener: its port, not the first one's
  python3 "$here/loopback_tcp_listener.py" "$1" >"$listener_log" &
  helpers="$helpers $!"
  polls=0
  until [ -s "$listener_log" ]; do
    polls=$((polls + 1))
    [ "$polls" -le 100 ] || fail "the $1 listener did not start"
    sleep 0.1
  done
  port="$(head -1 "$listener_log")"
}
listen silent
rc=0
start="$(date +%s)"
timeout 30 python3 "$subscriber" --types "$types" --seconds 1 --url "tcpq://127.0.0.1:$port" >"$work/silent.log" 2>&1 ||
  rc=$?
waited=$(($(date +%s) - start))
[ "$rc" -eq 2 ] || { cat "$work/silent.log"; fail "a silent tcpq server: exit $rc, expected 2"; }
grep -q -- "--url tcpq://127.0.0.1:$port: the server did not answer LCM's greeting within 1 s (is it an LCM tcpq server?)" \
  "$work/silent.log" || { cat "$work/silent.log"; fail "a silent tcpq server: not said"; }
[ "$waited" -le 10 ] || fail "a silent tcpq server: gave up after $waited s for --seconds 1"
no_traceback "$work/silent.log"
# Ctrl-C while it waits for the greeting: stopped before listening, exit 1,
# no traceback. (SIGINT's default action restored, as below.)
env --default-signal=INT python3 "$subscriber" --types "$types" --seconds 300 --url "tcpq://127.0.0.1:$port" \
  >"$work/silent-int.log" 2>&1 &
waiting=$!
polls=0
until [ "$(grep -c accepted "$listener_log")" -ge 2 ]; do
  polls=$((polls + 1))
  [ "$polls" -le 300 ] || { kill "$waiting"; fail "the subscriber did not connect to the silent server"; }
  sleep 0.1
done
sleep 0.2
kill -INT "$waiting"
ends_within "$waiting" 10 "Ctrl-C while waiting for a tcpq greeting: still running after 10 s"
rc=0
wait "$waiting" || rc=$?
no_traceback "$work/silent-int.log"
[ "$rc" -eq 1 ] || { cat "$work/silent-int.log"; fail "Ctrl-C while waiting for a tcpq greeting: exit $rc, expected 1"; }
grep -q "stopped before listening at tcpq://127.0.0.1:$port; no sim_stats" "$work/silent-int.log" ||
  { cat "$work/silent-int.log"; fail "Ctrl-C while waiting for a tcpq greeting: not said"; }
listen greet
rc=0
timeout 30 python3 "$subscriber" --types "$types" --seconds 1 --url "tcpq://127.0.0.1:$port" >"$work/greet.log" 2>&1 ||
  rc=$?
[ "$rc" -eq 1 ] || { cat "$work/greet.log"; fail "a tcpq server that greets: exit $rc, expected 1"; }
grep -q "no sim_stats at tcpq://127.0.0.1:$port in 1 s (is publish.lcm.enabled on?)" "$work/greet.log" ||
  { cat "$work/greet.log"; fail "greet"; }
# ... and SIGTERM while it listens to that server (nothing arrives): exit 1,
# and the summary names the time it listened, not the --seconds asked.
python3 "$subscriber" --types "$types" --seconds 300 --url "tcpq://127.0.0.1:$port" >"$work/greet-term.log" 2>&1 &
listening=$!
helpers="$helpers $listening"
polls=0
until [ "$(grep -c accepted "$listener_log")" -ge 4 ]; do  # the first run's two, then this one's
  polls=$((polls + 1))
  [ "$polls" -le 300 ] || fail "the subscriber did not connect to the greeting server"
  sleep 0.1
done
sleep 1
kill -TERM "$listening"
ends_within "$listening" 5 "SIGTERM while listening to a tcpq server: still running after 5 s"
rc=0
wait "$listening" || rc=$?
no_traceback "$work/greet-term.log"
[ "$rc" -eq 1 ] || { cat "$work/greet-term.log"; fail "SIGTERM while listening to a tcpq server: exit $rc, expected 1"; }
grep -q "no sim_stats at tcpq://127.0.0.1:$port in [0-9.]* s (stopped by SIGTERM before --seconds 300 ended; is publish.lcm.enabled on?)" \
  "$work/greet-term.log" || { cat "$work/greet-term.log"; fail "SIGTERM while listening to a tcpq server: no summary"; }
within "$(summary_s "$work/greet-term.log")" 0.5 10 ||
  { cat "$work/greet-term.log"; fail "SIGTERM while listening to a tcpq server: the summary does not name the time listened"; }
# A server that greets the probe and not LCM's own connection after it:
# LCM's client waited for that greeting for ever. Given min(--seconds, 10) s
# as the probe is: exit 2 naming --url and why, without a traceback.
listen greet-once
rc=0
start="$(date +%s)"
timeout 30 python3 "$subscriber" --types "$types" --seconds 1 --url "tcpq://127.0.0.1:$port" >"$work/once.log" 2>&1 ||
  rc=$?
waited=$(($(date +%s) - start))
[ "$rc" -eq 2 ] || { cat "$work/once.log"; fail "a tcpq server that greets the probe only: exit $rc, expected 2"; }
grep -q -- "--url tcpq://127.0.0.1:$port: LCM's own connection got no greeting within 1 s (the server answered the probe before it; is it still serving?)" \
  "$work/once.log" || { cat "$work/once.log"; fail "a tcpq server that greets the probe only: not said"; }
[ "$waited" -le 10 ] || fail "a tcpq server that greets the probe only: gave up after $waited s for --seconds 1"
[ "$(grep -c accepted "$listener_log")" -eq 2 ] || fail "a tcpq server that greets the probe only: LCM did not connect"
no_traceback "$work/once.log"
listen web
rc=0
timeout 30 python3 "$subscriber" --types "$types" --seconds 1 --url "tcpq://127.0.0.1:$port" >"$work/web.log" 2>&1 ||
  rc=$?
[ "$rc" -eq 2 ] || { cat "$work/web.log"; fail "a web server at tcpq://: exit $rc, expected 2"; }
grep -q -- "--url tcpq://127.0.0.1:$port: the server's answer is not LCM's" "$work/web.log" ||
  { cat "$work/web.log"; fail "a web server at tcpq://: not said"; }

# A tcpq server that greets and then stops in the middle of a message (the
# stall listener hangs: it answers no later connection either). LCM's client
# reads a message whole with a blocking recv(), which held the subscriber
# past --seconds for ever. The read is given until --seconds ends: exit 1 (no
# statistics), said with --url and why, without a traceback; LCM, its
# connection lost, is closed without waiting for the hung server again.
listen stall
rc=0
start="$(date +%s)"
timeout -k 5 30 python3 "$subscriber" --types "$types" --seconds 1 --url "tcpq://127.0.0.1:$port" \
  >"$work/midmsg.log" 2>&1 || rc=$?
waited=$(($(date +%s) - start))
no_traceback "$work/midmsg.log"
[ "$rc" -eq 1 ] || { cat "$work/midmsg.log"; fail "a tcpq server that stalls mid-message: exit $rc, expected 1"; }
grep -q -- "--url tcpq://127.0.0.1:$port: a message from the server was still incomplete when --seconds ended ([0-9.]* s after it began; has the server stalled?); it is dropped" \
  "$work/midmsg.log" || { cat "$work/midmsg.log"; fail "a tcpq server that stalls mid-message: not said"; }
grep -q "no sim_stats at tcpq://127.0.0.1:$port in 1 s (is publish.lcm.enabled on?)" "$work/midmsg.log" ||
  { cat "$work/midmsg.log"; fail "a tcpq server that stalls mid-message: no summary"; }
[ "$waited" -le 5 ] || fail "a tcpq server that stalls mid-message: ended after $waited s for --seconds 1"
# ... and SIGTERM during that read ends it at once, said, exit 1.
listen stall
python3 "$subscriber" --types "$types" --seconds 300 --url "tcpq://127.0.0.1:$port" >"$work/midmsg-term.log" 2>&1 &
midmsg=$!
helpers="$helpers $midmsg"
polls=0
until [ "$(grep -c accepted "$listener_log")" -ge 2 ]; do
  polls=$((polls + 1))
  [ "$polls" -le 300 ] || fail "the subscriber did not connect to the stalling server"
  sleep 0.1
done
sleep 1  # LCM's connection is made: it subscribes, and then waits in recv() for the rest of the message
kill -TERM "$midmsg"
ends_within "$midmsg" 5 "SIGTERM during a tcpq message that stalled: still running after 5 s"
rc=0
wait "$midmsg" || rc=$?
no_traceback "$work/midmsg-term.log"
[ "$rc" -eq 1 ] || { cat "$work/midmsg-term.log"; fail "SIGTERM during a tcpq message that stalled: exit $rc, expected 1"; }
grep -q -- "--url tcpq://127.0.0.1:$port: stopped by SIGTERM in the middle of a message from the server; it is dropped" \
  "$work/midmsg-term.log" || { cat "$work/midmsg-term.log"; fail "SIGTERM during a tcpq message that stalled: not said"; }
grep -q "no sim_stats at tcpq://127.0.0.1:$port in [0-9.]* s (stopped by SIGTERM before --seconds 300 ended; is publish.lcm.enabled on?)" \
  "$work/midmsg-term.log" || { cat "$work/midmsg-term.log"; fail "SIGTERM during a tcpq message that stalled: no summary"; }
within "$(summary_s "$work/midmsg-term.log")" 0.5 10 ||
  { cat "$work/midmsg-term.log"; fail "SIGTERM during a tcpq message that stalled: the summary does not name the time listened"; }
# ... and a SIGTERM that lands after the subscriber's select() and before
# LCM's recv() (signal_before_lcm_read.py sends it there) ends that read
# within moments too, not at the end of --seconds 30.
listen stall
rc=0
start="$(date +%s)"
timeout -k 5 60 python3 "$here/signal_before_lcm_read.py" "$subscriber" --types "$types" --seconds 30 \
  --url "tcpq://127.0.0.1:$port" >"$work/before-read.log" 2>&1 || rc=$?
waited=$(($(date +%s) - start))
no_traceback "$work/before-read.log"
[ "$rc" -eq 1 ] || { cat "$work/before-read.log"; fail "SIGTERM just before LCM's read: exit $rc, expected 1"; }
grep -q -- "--url tcpq://127.0.0.1:$port: stopped by SIGTERM in the middle of a message from the server; it is dropped" \
  "$work/before-read.log" || { cat "$work/before-read.log"; fail "SIGTERM just before LCM's read: not said"; }
[ "$waited" -le 5 ] || { cat "$work/before-read.log"; fail "SIGTERM just before LCM's read: ended after $waited s"; }
# A tcpq server that closes LCM's connection 1 s into listening: LCM has no
# socket then (and would reconnect, without a time limit, on the next
# handle()), so listening ends there, said with --url and when, without a
# traceback; exit 1 (no statistics), long before --seconds 10.
listen close
rc=0
start="$(date +%s)"
timeout -k 5 30 python3 "$subscriber" --types "$types" --seconds 10 --url "tcpq://127.0.0.1:$port" \
  >"$work/closed.log" 2>&1 || rc=$?
waited=$(($(date +%s) - start))
no_traceback "$work/closed.log"
grep -q closed "$listener_log" || { cat "$work/closed.log"; fail "the close listener did not close LCM's connection"; }
[ "$rc" -eq 1 ] || { cat "$work/closed.log"; fail "a tcpq server that closes the connection: exit $rc, expected 1"; }
grep -q -- "--url tcpq://127.0.0.1:$port: LCM lost its connection [0-9.]* s into --seconds (the server closed it, or a read failed); listening ended there" \
  "$work/closed.log" || { cat "$work/closed.log"; fail "a tcpq server that closes the connection: not said"; }
grep -q "no sim_stats at tcpq://127.0.0.1:$port in [0-9.]* s (LCM lost its connection before --seconds 10 ended)" \
  "$work/closed.log" || { cat "$work/closed.log"; fail "a tcpq server that closes the connection: no summary"; }
within "$(summary_s "$work/closed.log")" 0.5 5 ||
  { cat "$work/closed.log"; fail "a tcpq server that closes the connection: the summary does not name the time listened"; }
[ "$waited" -le 5 ] || fail "a tcpq server that closes the connection: ended after $waited s, 1 s after the close expected"

# Statistics whose real-time factor is NaN (a daemon before it has measured
# it) but whose time and tets are finite: printed, their tets plotted (every
# one: fewer than --plot-points), no NaN in the plot, exit 0.
python3 "$here/foreign_lcm_publisher.py" "$types" nan_rtf &
nan=$!
helpers="$helpers $nan"
rc=0
python3 "$subscriber" --types "$types" --seconds 1.5 --plot "$work/nanrtf.svg" >"$work/nanrtf.log" 2>"$work/nanrtf.err" ||
  rc=$?
kill "$nan"
[ "$rc" -eq 0 ] || { cat "$work/nanrtf.err"; fail "a NaN real-time factor: exit $rc, expected 0"; }
lines="$(grep -c '^t .*rtf   nan' "$work/nanrtf.log")"
[ "$lines" -ge 10 ] || { cat "$work/nanrtf.log" "$work/nanrtf.err"; fail "a NaN real-time factor: $lines lines printed"; }
[ -f "$work/nanrtf.svg" ] || { cat "$work/nanrtf.err"; fail "a NaN real-time factor: no plot"; }
points="$(sed -n 's/.*<polyline points="\([^"]*\)".*/\1/p' "$work/nanrtf.svg" | head -1 | wc -w)"
[ "$points" -eq "$lines" ] || fail "a NaN real-time factor: $points tets points for $lines statistics"
if grep -qi 'nan' "$work/nanrtf.svg"; then fail "a NaN real-time factor: NaN in the plot"; fi
grep -q "real-time factor: no finite values" "$work/nanrtf.svg" || fail "a NaN real-time factor: its panel does not say so"
# Statistics with no finite time: nothing can be plotted, so the plot asked
# for cannot be written (3, said); an earlier plot stays as it was.
printf 'an earlier plot\n' >"$work/nantime.svg"
python3 "$here/foreign_lcm_publisher.py" "$types" nan_time &
nan=$!
helpers="$helpers $nan"
rc=0
python3 "$subscriber" --types "$types" --seconds 1.5 --plot "$work/nantime.svg" >"$work/nantime.log" 2>"$work/nantime.err" ||
  rc=$?
kill "$nan"
lines="$(grep -c '^t ' "$work/nantime.log")"
[ "$rc" -eq 3 ] || { cat "$work/nantime.err"; fail "statistics without a finite time: exit $rc, expected 3"; }
grep -q "cannot write $work/nantime.svg: nothing to plot: none of the $lines sim_stats received has a finite time_s" \
  "$work/nantime.err" || { cat "$work/nantime.err"; fail "statistics without a finite time: not said"; }
[ "$(cat "$work/nantime.svg")" = "an earlier plot" ] || fail "statistics without a finite time: the earlier plot changed"

# The rest listens to a stream of statistics from the foreign publisher.
python3 "$here/foreign_lcm_publisher.py" "$types" stream &
stream=$!

# SIGTERM stops the subscriber early, and the plot is still written (this
# also waits until the stream flows).
python3 "$subscriber" --types "$types" --seconds 300 --plot "$work/term.svg" >"$work/term.log" 2>"$work/term.err" &
term=$!
polls=0
until [ "$(stats_lines "$work/term.log")" -ge 1 ]; do
  polls=$((polls + 1))
  [ "$polls" -le 600 ] || { kill "$term"; fail "no statistics in 60 s"; }
  sleep 0.1
done
kill -TERM "$term"
rc=0
wait "$term" || rc=$?
[ "$rc" -eq 0 ] || { cat "$work/term.err"; fail "stopped by SIGTERM: exit $rc, expected 0"; }
grep -q '<polyline' "$work/term.svg" || fail "no plot after SIGTERM"

# A standard output that closes (| head -1): printing stops, listening goes
# on, the plot is written, exit 0 without a traceback. A pipe holds a few
# hundred lines, so 1000 points show listening went on after the close.
{
  rc=0
  python3 "$subscriber" --types "$types" --seconds 3 --plot "$work/pipe.svg" 2>"$work/pipe.err" || rc=$?
  echo "$rc" >"$work/pipe.rc"
} | head -1 >"$work/pipe.head"
rc="$(cat "$work/pipe.rc")"
no_traceback "$work/pipe.err"
[ "$rc" -eq 0 ] || { cat "$work/pipe.err"; fail "standard output closed: exit $rc, expected 0"; }
grep -q '^t ' "$work/pipe.head" || fail "standard output closed: no first line"
[ -f "$work/pipe.svg" ] || { cat "$work/pipe.err"; fail "standard output closed: no plot"; }
points="$(sed -n 's/.*<polyline points="\([^"]*\)".*/\1/p' "$work/pipe.svg" | head -1 | wc -w)"
[ "$points" -ge 1000 ] || fail "standard output closed: $points points in the plot (listening stopped?)"

# What --plot names is written as the C++ tools write their -o
# (util::PendingOutputFile): a symbolic link stays a link and the file it
# names is replaced, with that file's permissions; an existing plot keeps its
# permissions; a FIFO and a file reached through /proc (a link to
# /proc/self/fd/1, as /dev/stdout is) are written in place, never renamed
# over. (Never /dev itself here: the test may run as root.)
mkdir "$work/plots"
printf 'old\n' >"$work/plots/real.svg"
chmod 640 "$work/plots/real.svg"
ln -s plots/real.svg "$work/link.svg"
printf 'old\n' >"$work/private.svg"
chmod 600 "$work/private.svg"
for plot in link.svg private.svg new.svg; do
  rc=0
  (umask 022 && exec python3 "$subscriber" --types "$types" --seconds 1 --plot "$work/$plot" >/dev/null 2>"$work/out.err") ||
    rc=$?
  [ "$rc" -eq 0 ] || { cat "$work/out.err"; fail "--plot $plot: exit $rc, expected 0"; }
done
[ -L "$work/link.svg" ] || fail "--plot at a symbolic link: the link was replaced by a file"
[ "$(readlink "$work/link.svg")" = plots/real.svg ] || fail "--plot at a symbolic link: it now names $(readlink "$work/link.svg")"
grep -q '<polyline' "$work/plots/real.svg" || fail "--plot at a symbolic link: the file it names was not written"
[ "$(stat -c %a "$work/plots/real.svg")" = 640 ] || fail "--plot at a symbolic link: mode $(stat -c %a "$work/plots/real.svg"), expected 640"
grep -q '<polyline' "$work/private.svg" || fail "--plot at a private file: not written"
[ "$(stat -c %a "$work/private.svg")" = 600 ] || fail "--plot at a private file: mode $(stat -c %a "$work/private.svg"), expected 600"
[ "$(stat -c %a "$work/new.svg")" = 644 ] || fail "--plot at a new file: mode $(stat -c %a "$work/new.svg") with umask 022"
if ls -A "$work" "$work/plots" | grep -q '\.tmp$'; then ls -A "$work" "$work/plots"; fail "a temporary plot was left"; fi
mkfifo "$work/plot.fifo"
cat "$work/plot.fifo" >"$work/fifo.out" &
reader=$!
helpers="$helpers $reader"
rc=0
python3 "$subscriber" --types "$types" --seconds 1 --plot "$work/plot.fifo" >/dev/null 2>"$work/fifo.err" || rc=$?
[ -p "$work/plot.fifo" ] || fail "--plot at a FIFO: the FIFO was replaced"
[ "$rc" -eq 0 ] || { cat "$work/fifo.err"; fail "--plot at a FIFO: exit $rc, expected 0"; }
wait "$reader"
grep -q '<polyline' "$work/fifo.out" || fail "--plot at a FIFO: nothing came through it"
# A FIFO that nobody reads: the plot waits for a reader for at most 10 s,
# and a stop signal during that wait ends it: exit 3 (the plot was not
# written), said. It waited in open() for ever, and Python retries an open
# that a signal interrupts (PEP 475), so only SIGKILL ended it. (SIGINT's
# default action restored, as below.)
mkfifo "$work/lonely.fifo"
env --default-signal=INT python3 "$subscriber" --types "$types" --seconds 300 --plot "$work/lonely.fifo" \
  >"$work/lonely.log" 2>"$work/lonely.err" &
lonely=$!
helpers="$helpers $lonely"
polls=0
until [ "$(stats_lines "$work/lonely.log")" -ge 1 ]; do
  polls=$((polls + 1))
  [ "$polls" -le 600 ] || fail "--plot at a FIFO without a reader: no statistics in 60 s"
  sleep 0.1
done
kill -INT "$lonely"  # ends the listening: the plot now waits for a reader
sleep 1
kill -INT "$lonely"
ends_within "$lonely" 5 "--plot at a FIFO without a reader: still running 5 s after a second SIGINT"
rc=0
wait "$lonely" || rc=$?
no_traceback "$work/lonely.err"
[ "$rc" -eq 3 ] || { cat "$work/lonely.err"; fail "--plot at a FIFO without a reader, stopped: exit $rc, expected 3"; }
grep -q "cannot write $work/lonely.fifo: no reader on the FIFO (stopped by SIGINT)" "$work/lonely.err" ||
  { cat "$work/lonely.err"; fail "--plot at a FIFO without a reader, stopped: not said"; }
# ... and without a signal the wait ends after 10 s, said the same way.
start="$(date +%s)"
rc=0
timeout 60 python3 "$subscriber" --types "$types" --seconds 1 --plot "$work/lonely.fifo" >/dev/null 2>"$work/lonely.err" ||
  rc=$?
waited=$(($(date +%s) - start))
[ "$rc" -eq 3 ] || { cat "$work/lonely.err"; fail "--plot at a FIFO without a reader: exit $rc, expected 3"; }
grep -q "cannot write $work/lonely.fifo: no reader on the FIFO within 10 s" "$work/lonely.err" ||
  { cat "$work/lonely.err"; fail "--plot at a FIFO without a reader: not said"; }
[ "$waited" -ge 10 ] && [ "$waited" -le 20 ] || fail "--plot at a FIFO without a reader: gave up after $waited s, expected 10"
[ -p "$work/lonely.fifo" ] || fail "--plot at a FIFO without a reader: the FIFO was replaced"
# A reader that opens the FIFO and stops reading: the plot (more than the
# pipe's 64 KiB: a second of the stream is thousands of points) is given
# 10 s to go through, then exit 3, said with how much the FIFO took. A
# blocking write waited for ever, and Ctrl-C could not end it.
mkfifo "$work/stall.fifo"
sleep 120 <"$work/stall.fifo" &
staller=$!
helpers="$helpers $staller"
start="$(date +%s)"
rc=0
timeout -k 5 60 python3 "$subscriber" --types "$types" --seconds 1 --plot "$work/stall.fifo" >/dev/null 2>"$work/stall.err" ||
  rc=$?
waited=$(($(date +%s) - start))
kill "$staller" 2>/dev/null || :  # gone if the reader was given its 120 s
no_traceback "$work/stall.err"
[ "$rc" -eq 3 ] || { cat "$work/stall.err"; fail "--plot at a FIFO whose reader stops reading: exit $rc, expected 3"; }
grep -q "cannot write $work/stall.fifo: the FIFO took [0-9]* of [0-9]* bytes in 10 s (has its reader stopped reading?)" \
  "$work/stall.err" || { cat "$work/stall.err"; fail "--plot at a FIFO whose reader stops reading: not said"; }
[ "$waited" -ge 10 ] && [ "$waited" -le 20 ] || fail "--plot at a FIFO whose reader stops reading: gave up after $waited s, expected 10"
# ... and a stop signal during that wait ends it at once, said the same way.
sleep 120 <"$work/stall.fifo" &
staller=$!
helpers="$helpers $staller"
env --default-signal=INT python3 "$subscriber" --types "$types" --seconds 1 --plot "$work/stall.fifo" \
  >"$work/stall-int.log" 2>"$work/stall-int.err" &
stalled=$!
helpers="$helpers $stalled"
polls=0
until [ "$(stats_lines "$work/stall-int.log")" -ge 1 ]; do
  polls=$((polls + 1))
  [ "$polls" -le 600 ] || fail "--plot at a stalled FIFO: no statistics in 60 s"
  sleep 0.1
done
sleep 3  # the rest of its second of listening; then the plot waits on the full pipe
kill -INT "$stalled"
ends_within "$stalled" 3 "--plot at a FIFO whose reader stops reading: still running 3 s after SIGINT"
rc=0
wait "$stalled" || rc=$?
kill "$staller" 2>/dev/null || :  # gone if the reader was given its 120 s
no_traceback "$work/stall-int.err"
[ "$rc" -eq 3 ] || { cat "$work/stall-int.err"; fail "--plot at a stalled FIFO, stopped: exit $rc, expected 3"; }
grep -q "cannot write $work/stall.fifo: the FIFO took [0-9]* of [0-9]* bytes (stopped by SIGINT)" \
  "$work/stall-int.err" || { cat "$work/stall-int.err"; fail "--plot at a stalled FIFO, stopped: not said"; }
ln -s /proc/self/fd/1 "$work/stdout"
rc=0
python3 "$subscriber" --types "$types" --seconds 1 --plot "$work/stdout" >"$work/stdout.out" 2>"$work/stdout.err" || rc=$?
[ -L "$work/stdout" ] || fail "--plot through /proc: the link was replaced by a file"
[ "$rc" -eq 0 ] || { cat "$work/stdout.err"; fail "--plot through /proc: exit $rc, expected 0"; }
grep -q '^t ' "$work/stdout.out" || fail "--plot through /proc: the statistics printed before it are gone"
[ "$(tail -1 "$work/stdout.out")" = '</svg>' ] || { tail -2 "$work/stdout.out"; fail "--plot through /proc: the plot does not end standard output"; }
grep -q "^wrote $work/stdout (" "$work/stdout.err" || { cat "$work/stdout.err"; fail "--plot through /proc: 'wrote' not on stderr"; }
# ... and when that standard output has closed (| head -1) the plot cannot
# be written: exit 3, said.
{
  rc=0
  python3 "$subscriber" --types "$types" --seconds 1 --plot "$work/stdout" 2>"$work/stdout-closed.err" || rc=$?
  echo "$rc" >"$work/stdout-closed.rc"
} | head -1 >/dev/null
rc="$(cat "$work/stdout-closed.rc")"
[ "$rc" -eq 3 ] || { cat "$work/stdout-closed.err"; fail "--plot to a closed standard output: exit $rc, expected 3"; }
grep -q "cannot write $work/stdout: standard output has closed" "$work/stdout-closed.err" ||
  { cat "$work/stdout-closed.err"; fail "--plot to a closed standard output: not said"; }

# A plot that cannot be written (file size limit): exit 3 with the reason,
# the earlier plot unchanged, no temporary file left. stdout goes to
# /dev/null, which the limit does not cover.
printf 'an earlier plot\n' >"$work/keep.svg"
rc=0
(ulimit -f 1 && exec python3 "$subscriber" --types "$types" --seconds 2 --plot "$work/keep.svg" \
  >/dev/null 2>"$work/keep.err") || rc=$?
[ "$rc" -eq 3 ] || { cat "$work/keep.err"; fail "an unwritable plot: exit $rc, expected 3"; }
grep -q "cannot write $work/keep.svg: File too large" "$work/keep.err" || { cat "$work/keep.err"; fail "no reason"; }
no_traceback "$work/keep.err"
[ "$(cat "$work/keep.svg")" = "an earlier plot" ] || fail "the earlier plot was changed: $(head -c 200 "$work/keep.svg")"
if ls -A "$work" | grep -q '^\.keep\.svg\..*\.tmp$'; then ls -A "$work"; fail "a temporary plot was left"; fi

# More statistics than the plot keeps, then Ctrl-C: the plot is still written,
# with at most 10000 points per line (thinned evenly: at least half of them).
# SIGINT's default action is restored for this background job (sh ignores it).
env --default-signal=INT python3 "$subscriber" --types "$types" --seconds 300 --plot "$work/many.svg" \
  >"$work/many.log" 2>"$work/many.err" &
many=$!
polls=0
until [ "$(stats_lines "$work/many.log")" -gt 10000 ]; do
  polls=$((polls + 1))
  [ "$polls" -le 1200 ] || { kill "$many"; fail "fewer than 10001 statistics in 120 s"; }
  sleep 0.1
done
kill -INT "$many"
rc=0
wait "$many" || rc=$?
[ "$rc" -eq 0 ] || { cat "$work/many.err"; fail "stopped by SIGINT: exit $rc, expected 0"; }
no_traceback "$work/many.err"
received="$(grep -c '^t ' "$work/many.log")"
points="$(sed -n 's/.*<polyline points="\([^"]*\)".*/\1/p' "$work/many.svg" | head -1 | wc -w)"
echo "the plot of $received statistics holds $points points"
[ "$points" -le 10000 ] && [ "$points" -ge 5000 ] || fail "$points points for $received statistics"
grep -q "^wrote $work/many.svg ($points of $received points)" "$work/many.log" || { tail -2 "$work/many.log"; fail "no summary"; }
