"""Graph capture and replay (Warp's ``capture_*`` API): see ``capture`` and docs/runtime.md."""
