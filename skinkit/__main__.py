from skinkit.cli import main

main()
