#!/usr/bin/python3
"""candump logs through Debian's python3-can (can.CanutilsLogReader / CanutilsLogWriter), for the
interoperability test (test_candump_python_can.cpp).

  python_can_log.py read LOG    print every message of LOG, one canonical line each
  python_can_log.py write LOG   write a fixed set of messages to LOG, print them the same way
Canonical line: "<usec since epoch> <id hex> <ext 0/1> <rtr 0/1> <err 0/1> <dlc> <data hex>".
"""
import sys

import can


def canon(m):
    usec = int(round(m.timestamp * 1e6))
    return "%d %x %d %d %d %d %s" % (usec, m.arbitration_id, int(m.is_extended_id), int(m.is_remote_frame),
                                     int(m.is_error_frame), m.dlc, bytes(m.data).hex())


def main():
    if len(sys.argv) != 3 or sys.argv[1] not in ("read", "write"):
        print(__doc__, file=sys.stderr)
        return 2
    mode, path = sys.argv[1], sys.argv[2]
    if mode == "read":
        for m in can.CanutilsLogReader(path):
            print(canon(m))
        return 0
    msgs = [
        can.Message(timestamp=1700000000.000001, arbitration_id=0x123, is_extended_id=False, data=[1, 2, 3]),
        can.Message(timestamp=1700000000.250000, arbitration_id=0x1ABCDEF0, is_extended_id=True, data=[]),
        can.Message(timestamp=1700000000.500000, arbitration_id=0x7FF, is_extended_id=False, data=list(range(0xF8, 0x100))),
        can.Message(timestamp=1700000001.000000, arbitration_id=0x02D, is_extended_id=False, is_remote_frame=True, dlc=0),
        can.Message(timestamp=1700000001.123456, arbitration_id=0x000, is_extended_id=False, data=[0]),
        can.Message(timestamp=1700000002.999999, arbitration_id=0x1FFFFFFF, is_extended_id=True, data=[0xDE, 0xAD, 0xBE, 0xEF]),
    ]
    w = can.CanutilsLogWriter(path, channel="can0")
    for m in msgs:
        w.on_message_received(m)
    w.stop()
    for m in msgs:
        print(canon(m))
    return 0


if __name__ == "__main__":
    sys.exit(main())
