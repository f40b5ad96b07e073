"""JSON schemas of the project's files (calib.json, camera.json, board.json...), read as
package data."""
