#!/usr/bin/env python3
"""Writes src/visual/tags/aruco_codes.rs: OpenCV's predefined ArUco dictionaries as printed.

Each marker is read from OpenCV's own drawing (cv2.aruco.generateImageMarker with a one-cell
black border), so the table is what a printed marker shows, whatever OpenCV's internal byte
order: bit (row r, column c) of an n x n marker is bit n*n-1-(r*n+c) of its code (row-major
from the top-left, most significant first), 1 where white. The _50, _100 and _250 dictionaries
are the first codes of the _1000 one (checked here). Also written: each dictionary's
maxCorrectionBits and its minimum Hamming distance over the four rotations (computed here).
DICT_ARUCO_ORIGINAL is left out: two of its codes are rotations of each other (distance 0).

Usage: pip install opencv-python-headless; python3 scripts/aruco_codes.py > src/visual/tags/aruco_codes.rs
"""
import cv2
import numpy as np

A = cv2.aruco


def codes(dictionary, n):
    out = []
    for i in range(dictionary.bytesList.shape[0]):
        im = A.generateImageMarker(dictionary, i, n + 2, borderBits=1)
        bits = (im[1:-1, 1:-1] > 127).astype(np.uint64).ravel()
        code = 0
        for b in bits:
            code = (code << 1) | int(b)
        out.append(code)
    return out


def rotations(code, n):
    m = np.array([(code >> (n * n - 1 - k)) & 1 for k in range(n * n)]).reshape(n, n)
    out = []
    for _ in range(4):
        v = 0
        for b in m.ravel():
            v = (v << 1) | int(b)
        out.append(v)
        m = np.rot90(m)
    return out


def min_hamming(cs, n):
    rot = [rotations(c, n) for c in cs]
    best = n * n
    for i, c in enumerate(cs):
        for r in rot[i][1:]:
            best = min(best, bin(c ^ r).count("1"))
        for j in range(i):
            for r in rot[j]:
                best = min(best, bin(c ^ r).count("1"))
    return best


def main():
    tables = []
    for n in (4, 5, 6, 7):
        big = A.getPredefinedDictionary(getattr(A, f"DICT_{n}X{n}_1000"))
        cs = codes(big, n)
        entries = []
        for count in (50, 100, 250, 1000):
            d = A.getPredefinedDictionary(getattr(A, f"DICT_{n}X{n}_{count}"))
            assert np.array_equal(d.bytesList, big.bytesList[:count])
            entries.append((f"DICT_{n}X{n}_{count}", count, d.maxCorrectionBits, min_hamming(cs[:count], n)))
        tables.append((f"ARUCO_{n}X{n}", n, cs, entries))

    print("//! OpenCV's predefined ArUco dictionaries, as printed: written by `scripts/aruco_codes.py`")
    print(f"//! from OpenCV {cv2.__version__} (Apache 2.0; the dictionaries come from the ArUco library,")
    print("//! BSD). Bit (row r, column c) of an n x n marker is bit n*n-1-(r*n+c) of its code, 1 where")
    print("//! white. Do not edit by hand.")
    print()
    print("/// One dictionary: its OpenCV name, marker cells across, the table its codes start, how many")
    print("/// codes it takes, OpenCV's `maxCorrectionBits` and the minimum Hamming distance between any")
    print("/// two of its codes in any rotation.")
    print("pub(super) struct ArucoEntry {")
    print("    pub name: &'static str,")
    print("    pub cells: usize,")
    print("    pub codes: &'static [u64],")
    print("    pub count: usize,")
    print("    pub max_correction_bits: u32,")
    print("    pub min_hamming: u32,")
    print("}")
    print()
    print("/// Every dictionary, in OpenCV's order.")
    print("pub(super) static DICTIONARIES: [ArucoEntry; %d] = [" % sum(len(t[3]) for t in tables))
    for table, n, _, entries in tables:
        for name, count, mcb, mh in entries:
            print(f"    ArucoEntry {{ name: \"{name}\", cells: {n}, codes: &{table}, count: {count}, max_correction_bits: {mcb}, min_hamming: {mh} }},")
    print("];")
    for table, n, cs, _ in tables:
        print()
        print(f"static {table}: [u64; {len(cs)}] = [")
        width = (n * n + 3) // 4
        for k in range(0, len(cs), 6):
            print("    " + " ".join(f"0x{c:0{width}x}," for c in cs[k:k + 6]))
        print("];")


if __name__ == "__main__":
    main()
