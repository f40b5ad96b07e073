"""Adept V+ and Kawasaki AS: location files and programs read as targets, and written back
losslessly (locations as Z-Y-Z Euler degrees in mm, precision points as joints)."""
