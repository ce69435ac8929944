"""Reads a `hybridnav export` directory with the tools users pair it with, and checks it.

- Every NMEA sentence parses with pynmea2 with checksum verification on, and the truth
  file's GGA positions agree with truth.csv.
- scene.geojson is valid GeoJSON by the `geojson` package, with RFC 7946 rules checked
  here (closed, counter-clockwise exterior rings; lon/lat in range).
- scene.kml is well-formed XML in the KML 2.2 namespace.
- Every Parquet table equals its CSV twin (pandas).

Usage: export_check.py DIR. Prints one line per check; exits non-zero on the first failure.
"""

import glob
import math
import os
import sys
import xml.etree.ElementTree as ET

import geojson
import pandas as pd
import pynmea2

d = sys.argv[1]


def fail(msg):
    print("FAIL:", msg)
    sys.exit(1)


# NMEA: checksums and the truth positions.
n_sentences = 0
for path in sorted(glob.glob(os.path.join(d, "*.nmea"))):
    with open(path, newline="") as f:
        raw = f.read()
    if "\n" in raw.replace("\r\n", ""):
        fail(f"{path}: a line not ended by CR LF")
    for line in raw.split("\r\n"):
        if not line:
            continue
        # NMEA 0183 §5.3: at most 82 characters from "$" to CR LF.
        if len(line) + 2 > 82:
            fail(f"{path}: {len(line) + 2} characters: {line!r}")
        try:
            pynmea2.parse(line, check=True)
        except pynmea2.ParseError as e:
            fail(f"{path}: {line!r}: {e}")
        n_sentences += 1
print(f"nmea: {n_sentences} sentences parsed with checksums verified")

truth = pd.read_csv(os.path.join(d, "truth.csv"))
ggas = []
with open(os.path.join(d, "truth.nmea"), newline="") as f:
    for line in f.read().split("\r\n"):
        if line.startswith("$GNGGA"):
            ggas.append(pynmea2.parse(line, check=True))
if len(ggas) != len(truth):
    fail(f"truth.nmea has {len(ggas)} GGA sentences for {len(truth)} truth epochs")
worst_deg = 0.0
worst_h = 0.0
for g, (_, t) in zip(ggas, truth.iterrows()):
    worst_deg = max(worst_deg, abs(g.latitude - t.lat_deg), abs(g.longitude - t.lon_deg))
    worst_h = max(worst_h, abs(float(g.altitude) + float(g.geo_sep) - t.h_m))
# 6 decimals of a minute: half a unit is 8.3e-9 degrees; altitude to the millimetre.
if worst_deg > 8.4e-9 or worst_h > 6e-4:
    fail(f"GGA vs truth: {worst_deg:.3g} deg, {worst_h:.3g} m")
print(f"nmea: GGA positions match truth.csv within {worst_deg:.2g} deg and {worst_h:.2g} m")

# GeoJSON.
with open(os.path.join(d, "scene.geojson")) as f:
    gj = geojson.load(f)
if not gj.is_valid:
    fail(f"geojson: {gj.errors()}")
if "crs" in gj:
    fail("geojson: a crs member (RFC 7946 §4 removed it)")
kinds = {}
for feat in gj["features"]:
    geom = feat["geometry"]
    kinds[feat["properties"]["kind"]] = kinds.get(feat["properties"]["kind"], 0) + 1
    if geom["type"] == "Polygon":
        ring = geom["coordinates"][0]
        if ring[0] != ring[-1]:
            fail("geojson: an open ring")
        area2 = sum(a[0] * b[1] - b[0] * a[1] for a, b in zip(ring, ring[1:]))
        if area2 <= 0:
            fail("geojson: a clockwise exterior ring")
        pts = ring
    elif geom["type"] == "LineString":
        pts = geom["coordinates"]
    else:
        pts = [geom["coordinates"]]
    for p in pts:
        if not (-180 <= p[0] <= 180 and -90 <= p[1] <= 90):
            fail(f"geojson: position out of range {p}")
print("geojson: valid;", ", ".join(f"{k} {v}" for k, v in sorted(kinds.items())))

# KML.
root = ET.parse(os.path.join(d, "scene.kml")).getroot()
ns = "{http://www.opengis.net/kml/2.2}"
if root.tag != ns + "kml":
    fail(f"kml: root element {root.tag}")
placemarks = root.findall(f".//{ns}Placemark")
for pm in placemarks:
    for c in pm.iter(ns + "coordinates"):
        for tup in c.text.split():
            lon, lat, _h = (float(x) for x in tup.split(","))
            if not (-180 <= lon <= 180 and -90 <= lat <= 90):
                fail(f"kml: coordinate out of range {tup}")
print(f"kml: well-formed, {len(placemarks)} placemarks")

# Parquet = CSV.
n_tables = 0
for pq in sorted(glob.glob(os.path.join(d, "*.parquet"))):
    csv = pq[: -len(".parquet")] + ".csv"
    a = pd.read_parquet(pq)
    b = pd.read_csv(csv, keep_default_na=False, na_values=[""])
    if list(a.columns) != list(b.columns) or len(a) != len(b):
        fail(f"{pq}: columns or rows differ from the CSV")
    for col in a.columns:
        x, y = a[col], b[col]
        if x.dtype.kind == "f":
            same = ((x == y) | (x.isna() & y.isna())).all()
        else:
            same = (x.astype(str) == y.astype(str)).all()
        if not same:
            fail(f"{pq}: column {col} differs from the CSV")
    n_tables += 1
print(f"tables: {n_tables} Parquet tables equal their CSV")
