"""Reading and writing media files (videos, image strips)."""
