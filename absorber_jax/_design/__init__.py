"""Design: band objectives, exact and robust peaks, tuning."""
