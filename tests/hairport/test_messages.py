"""Error details: bounded, printable, no storage names."""

from hairport.messages import MAX_DETAIL_CHARS, STORED_FILE, safe_detail


def test_a_long_detail_is_cut():
    detail = safe_detail("no job " + "x" * 1_000_000)
    assert len(detail) == MAX_DETAIL_CHARS and detail.endswith("\u2026")


def test_control_characters_and_nul_are_dropped():
    assert safe_detail("no job a\x00b\nc\x1b[31m") == "no job a b c [31m"


def test_blob_names_are_hidden():
    sha = "ab" * 32
    assert safe_detail(f"topology differs: /data/blobs/ab/{sha}.obj has 3 vertices") == \
        f"topology differs: {STORED_FILE} has 3 vertices"
    assert sha not in safe_detail(f"gone: {sha[:12]}... {sha}")
