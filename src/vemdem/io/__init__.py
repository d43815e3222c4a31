"""Writers: CSV, JSON summaries, ParaView series, checkpoints."""
