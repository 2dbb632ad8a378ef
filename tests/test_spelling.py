"""The prose of eppf and of its documentation uses one spelling, American (as scikit-learn)."""
import importlib.util
import pathlib

ROOT = pathlib.Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("american_spelling", ROOT / "scripts" / "american_spelling.py")
spelling = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(spelling)


def test_rules_rewrite_british_spellings_only():
    assert spelling._american("Neighbours are centred, normalised and colour-coded; the Centre") == (
        "Neighbors are centered, normalized and color-coded; the Center")
    assert spelling._american("NORMALISATION of the centres, modelling") == "NORMALIZATION of the centers, modeling"
    # words that only look British stay as they are
    text = "optimistic characteristics of the analyses, a centroid, a specialist, otherwise precise"
    assert spelling._american(text) == text


def test_prose_is_american(capsys):
    status = spelling.main([])
    assert status == 0, capsys.readouterr().out
