"""Reading and writing: volume loaders, phantoms, render results, atomic file output."""
